"""The inspection verdict: pass, check or fail, from a result's lane figures against versioned thresholds.

The lane figures (EUSAMA %, least phase shift, left/right imbalance; estimator.inspection) are estimates
made from displacements and the identified model, not from a force plate. The verdict judges those
figures the way inspection practice does, so a lane can compare; the damper curve is the product's own
result and is not judged here.

Default thresholds and where they come from:
- EGEA SPECSUS2018 (phase-shift method): a least phase shift below 35 degrees fails.
- EUSAMA practice: road holding of 40% or more is sufficient, 20-40% is doubtful (check), below 20% is bad.
- Left/right on an axle: a relative EUSAMA difference above 20% fails, above 15% calls for a check
  (|L - R| / max(L, R); practice names 15-20%).
CITA Recommendation 26 could not be consulted; the figures above are the ones published practice uses.
A site sets its own (`shockbench serve --verdict-thresholds FILE.toml`); every verdict names the version
of the thresholds it was judged by.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from enum import StrEnum
from typing import Any

from estimator.errors import UserError


class Outcome(StrEnum):
    PASS = "pass"
    CHECK = "check"
    FAIL = "fail"


_SEVERITY = {Outcome.PASS: 0, Outcome.CHECK: 1, Outcome.FAIL: 2}


class ThresholdsError(UserError, ValueError):
    """A thresholds file or table that cannot be used (one line, naming the problem)."""


@dataclass(frozen=True)
class VerdictThresholds:
    """The limits a verdict is judged by. All in the units of the lane figures (degrees, %)."""

    version: str = "shockbench-default-2026.1"
    """Named in every verdict, so that a result says which limits judged it."""
    phase_fail_below_deg: float = 35.0
    """EGEA SPECSUS2018: a least phase shift below this fails."""
    eusama_pass_from_percent: float = 40.0
    """EUSAMA practice: at or above this, sufficient."""
    eusama_fail_below_percent: float = 20.0
    """EUSAMA practice: below this, bad; in between, check."""
    imbalance_check_above_percent: float = 15.0
    """Axle: relative left/right EUSAMA difference above this calls for a check."""
    imbalance_fail_above_percent: float = 20.0
    """Axle: above this, fail."""

    def __post_init__(self) -> None:
        if not self.version.strip():
            raise ThresholdsError("verdict thresholds: version must not be empty")
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name != "version" and not (isinstance(value, int | float) and math.isfinite(value)):
                raise ThresholdsError(f"verdict thresholds: {f.name} must be a finite number, not {value!r}")
        if self.eusama_fail_below_percent > self.eusama_pass_from_percent:
            raise ThresholdsError(
                "verdict thresholds: eusama_fail_below_percent must not exceed eusama_pass_from_percent"
            )
        if self.imbalance_check_above_percent > self.imbalance_fail_above_percent:
            raise ThresholdsError(
                "verdict thresholds: imbalance_check_above_percent must not exceed "
                "imbalance_fail_above_percent"
            )

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> VerdictThresholds:
        """From a TOML table (unknown keys refused, by name); missing keys keep their defaults."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ThresholdsError(
                f"verdict thresholds: unknown key {unknown[0]!r} (known: {', '.join(sorted(known))})"
            )
        values = dict(table)
        if "version" in values:
            values["version"] = str(values["version"])
        return cls(**values)


@dataclass(frozen=True)
class Verdict:
    outcome: Outcome
    reasons: list[str] = field(default_factory=list)
    """One line per figure that made it check or fail; a missing figure is a check."""
    thresholds: VerdictThresholds = field(default_factory=VerdictThresholds)

    def as_dict(self) -> dict[str, Any]:
        thresholds = asdict(self.thresholds)
        return {
            "outcome": self.outcome.value,
            "thresholds_version": thresholds.pop("version"),
            "reasons": list(self.reasons),
            "thresholds": thresholds,
        }


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else None


def _judge_corner(
    name: str, figures: Mapping[str, Any], limits: VerdictThresholds
) -> list[tuple[Outcome, str]]:
    found: list[tuple[Outcome, str]] = []
    prefix = f"{name}: " if name else ""
    phase = _number(figures.get("phase_shift_min_deg"))
    if phase is None:
        found.append((Outcome.CHECK, f"{prefix}the least phase shift could not be estimated"))
    elif phase < limits.phase_fail_below_deg:
        found.append(
            (Outcome.FAIL, f"{prefix}least phase shift {phase:.1f}° below {limits.phase_fail_below_deg:g}°")
        )
    eusama = _number(figures.get("eusama_percent"))
    if eusama is None:
        found.append((Outcome.CHECK, f"{prefix}EUSAMA could not be estimated"))
    elif eusama < limits.eusama_fail_below_percent:
        found.append(
            (Outcome.FAIL, f"{prefix}EUSAMA {eusama:.1f}% below {limits.eusama_fail_below_percent:g}%")
        )
    elif eusama < limits.eusama_pass_from_percent:
        found.append(
            (
                Outcome.CHECK,
                f"{prefix}EUSAMA {eusama:.1f}% between {limits.eusama_fail_below_percent:g}% and "
                f"{limits.eusama_pass_from_percent:g}%",
            )
        )
    return found


def relative_difference_percent(left: float, right: float) -> float:
    """|left - right| / max(left, right) in %, 0 when both are 0."""
    larger = max(abs(left), abs(right))
    return 0.0 if larger == 0 else 100.0 * abs(left - right) / larger


def imbalance_outcome(difference_percent: float, limits: VerdictThresholds) -> Outcome:
    """How an axle's left/right EUSAMA difference (relative_difference_percent) is judged."""
    if difference_percent > limits.imbalance_fail_above_percent:
        return Outcome.FAIL
    return Outcome.CHECK if difference_percent > limits.imbalance_check_above_percent else Outcome.PASS


def judge(inspection: Mapping[str, Any], limits: VerdictThresholds | None = None) -> Verdict:
    """The verdict on a result's `inspection` (as `identify --json` writes it): a corner's figures, or an
    axle's `left`, `right` (and `imbalance`)."""
    limits = limits or VerdictThresholds()
    found: list[tuple[Outcome, str]] = []
    if "left" in inspection and "right" in inspection:
        left, right = inspection["left"], inspection["right"]
        found += _judge_corner("left", left, limits) + _judge_corner("right", right, limits)
        eusama_l, eusama_r = _number(left.get("eusama_percent")), _number(right.get("eusama_percent"))
        if eusama_l is not None and eusama_r is not None:
            difference = relative_difference_percent(eusama_l, eusama_r)
            differ = f"left/right EUSAMA differ by {difference:.1f}%"
            outcome = imbalance_outcome(difference, limits)
            if outcome is not Outcome.PASS:
                above = {
                    Outcome.FAIL: limits.imbalance_fail_above_percent,
                    Outcome.CHECK: limits.imbalance_check_above_percent,
                }[outcome]
                found.append((outcome, f"{differ} (> {above:g}%)"))
    else:
        found += _judge_corner("", inspection, limits)
    outcome = max((o for o, _ in found), key=_SEVERITY.__getitem__, default=Outcome.PASS)
    return Verdict(outcome, [reason for _, reason in found], limits)
