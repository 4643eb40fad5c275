"""The outcome of one rig of bench_lab_rig.py (what it scores item 5 of issue 29 by) and the report printed
from a set of them, from a run or from its --results file (JSON lines of Outcome)."""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field

RATE_EFFECTS = {
    "spring_curve": ("spring_stiffness", "rate_at_static_load_N_per_m"),
    "tyre_stiffness": ("tyre_stiffness", "tyre_stiffness_N_per_m"),
}
"""The doctor's families that correct a stated rate (estimator.doctor.catalog): family -> the rate's name
here and the key of the rate it fitted in its parameters (estimator.doctor.parameters.report)."""
LIMIT_PERCENT = 40.0


@dataclass(frozen=True)
class Outcome:
    seed: int
    description: str
    true_spring_N_per_m: float
    true_tyre_N_per_m: float
    named: tuple[str, ...]
    rates_named: dict[str, float]
    """effect -> the rate the doctor corrected to (N/m), as its final model has it (DiagnosisResult's
    final_parameters: the model validated on run B; results files before 2026-11-30 hold the step's)."""
    unexplained: bool
    conclusion: str
    located: str
    doctor_before_percent: float | None
    doctor_after_percent: float | None
    doctor_heldout_percent: float | None
    mass_only_in_sample_percent: float | None
    mass_only_heldout_percent: float | None
    mass_only_rates_N_per_m: tuple[float, float] | None
    unrecorded_percent: float | None
    """What no model driven by the recorded plate can predict on run B (unpredictable_percent)."""
    own_physics_percent: float | None
    """The rig's own physics without the unrecorded force, held out on run B (own_physics_percent)."""
    mass_only_refined_heldout_percent: float | None
    """Mass-only identify with its output-error refinement (`identify --refine`), held out on run B."""
    simulate_s: float
    doctor_s: float
    identify_s: float
    error: str = ""

    stated_spring_N_per_m: float | None = None
    stated_tyre_N_per_m: float | None = None
    doctor_curve_percent: float | None = None
    """The doctor's final model's damper curve against the rig's own damper ((d) of the module docstring)."""
    mass_only_curve_percent: float | None = None
    mass_only_refined_curve_percent: float | None = None
    rates_at_step: dict[str, float] = field(default_factory=dict)
    """effect -> the rate as named at its step (results files before 2026-11-30: not recorded)."""

    @property
    def both_named(self) -> bool:
        """Both rate families named (each rig's file states both rates 40-80% off)."""
        return all(name in self.named for name in RATE_EFFECTS)  # the families: they take no channel

    @property
    def rates_right(self) -> bool:
        """Both rates named, each corrected toward the truth: closer to it than the rate stated (a rig of a
        results file without the stated rates: named)."""
        return self._closer(self.rates_named)

    @property
    def rates_right_at_step(self) -> bool | None:
        """rates_right with the rates as named at their steps (None: not recorded)."""
        return self._closer(self.rates_at_step) if self.rates_at_step or not self.both_named else None

    def _closer(self, rates: dict[str, float]) -> bool:
        if not self.both_named or self.stated_spring_N_per_m is None or self.stated_tyre_N_per_m is None:
            return self.both_named
        truth = {"spring_stiffness": self.true_spring_N_per_m, "tyre_stiffness": self.true_tyre_N_per_m}
        stated = {"spring_stiffness": self.stated_spring_N_per_m, "tyre_stiffness": self.stated_tyre_N_per_m}
        return all(
            abs(rates[family] - truth[rate]) < abs(stated[rate] - truth[rate])
            for family, (rate, _) in RATE_EFFECTS.items()
        )

    @property
    def doctor_meets(self) -> bool:
        """Item 5 for the doctor: rate corrections named (rates_right), held-out gap ≤ 40%, unexplained."""
        return self.rates_right and _within(self.doctor_heldout_percent) and self.unexplained

    @property
    def mass_only_meets(self) -> bool:
        return _within(self.mass_only_heldout_percent)


def _within(percent: float | None) -> bool:
    """A gap (%) within item 5's bound; None (diverged) is not."""
    return percent is not None and percent <= LIMIT_PERCENT


def percent_cell(value: float | None) -> str:
    return "diverged" if value is None else f"{value:.0f}%"


def _curve(value: float | None) -> str:
    return "—" if value is None else f"{value:.1f}%"


def named_text(o: Outcome) -> str:
    truth = {"spring_stiffness": o.true_spring_N_per_m, "tyre_stiffness": o.true_tyre_N_per_m}
    parts = []
    for name in o.named:
        if name in o.rates_named:
            rate, true = o.rates_named[name], truth[RATE_EFFECTS[name][0]]
            parts.append(f"{name} {rate:.0f} ({100 * (rate / true - 1):+.0f}% of true)")
        else:
            parts.append(name)
    return ", ".join(parts) or "nothing"


def _median(values: list[float | None]) -> str:
    """The median, a diverged gap (None) counting as the largest."""
    ordered = sorted(math.inf if v is None else v for v in values)
    if not ordered:
        return "—"
    middle = statistics.median(ordered)
    return percent_cell(middle if math.isfinite(middle) else None)


SENSOR_FAMILIES = ("sensor_dynamics", "sensor_gain", "sensor_offset")


def print_report(outcomes: list[Outcome]) -> None:
    print(
        "\n| rig | doctor named (rate, error against the truth) | verdict | doctor gap A: before → after "
        "| doctor held-out B | mass-only identify A / held-out B / refined held-out B | unpredictable B "
        "| own physics B | curve against the damper: doctor / identify / refined | doctor (s) |"
    )
    print("|---:|---|---|---|---:|---|---:|---:|---|---:|")
    for o in outcomes:
        verdict = "unexplained" if o.unexplained else ("error" if o.error else "explained")
        print(
            f"| {o.seed} | {named_text(o)} | {verdict} | {percent_cell(o.doctor_before_percent)} → "
            f"{percent_cell(o.doctor_after_percent)} | {percent_cell(o.doctor_heldout_percent)} | "
            f"{percent_cell(o.mass_only_in_sample_percent)} / {percent_cell(o.mass_only_heldout_percent)} / "
            f"{percent_cell(o.mass_only_refined_heldout_percent)} | {percent_cell(o.unrecorded_percent)} | "
            f"{percent_cell(o.own_physics_percent)} | {_curve(o.doctor_curve_percent)} / "
            f"{_curve(o.mass_only_curve_percent)} / {_curve(o.mass_only_refined_curve_percent)} | "
            f"{o.doctor_s:.0f} |"
        )
    print(
        "\nGaps are % of the response RMS (measured body and wheel motion about their means) of that run. "
        "Unpredictable B: run B without the coil's unrecorded reference command against B as measured "
        "(unpredictable_percent), a floor of any held-out gap. Own physics B: the rig's true physics without "
        "the coil, cogging and cable (own_physics_percent), what a model right in every constant scores. "
        "Curve against the damper: RMS of the model's damper curve minus the rig's own damper (viscous and "
        "its guide's friction) over run A's excited suspension rates, % of the damper's peak there."
    )
    print("\nRigs:")
    for o in outcomes:
        print(f"- {o.description}")
        if o.mass_only_rates_N_per_m is not None:
            spring, tyre = o.mass_only_rates_N_per_m
            spring_error, tyre_error = spring / o.true_spring_N_per_m - 1, tyre / o.true_tyre_N_per_m - 1
            print(
                f"  mass-only identify: spring {spring:.0f} N/m ({100 * spring_error:+.0f}% of true), "
                f"tyre {tyre:.0f} N/m ({100 * tyre_error:+.0f}%)"
            )
        if o.located:
            print(f"  doctor, where: {o.located}")
        if o.error:
            print(f"  ERROR: {o.error}")
    count = len(outcomes)
    held_within = sum(_within(o.doctor_heldout_percent) for o in outcomes)
    medians = {
        "doctor gap on A before": _median([o.doctor_before_percent for o in outcomes]),
        "after": _median([o.doctor_after_percent for o in outcomes]),
        "doctor held-out on B": _median([o.doctor_heldout_percent for o in outcomes]),
        "mass-only identify on A": _median([o.mass_only_in_sample_percent for o in outcomes]),
        "mass-only held-out on B": _median([o.mass_only_heldout_percent for o in outcomes]),
        "mass-only refined held-out on B": _median([o.mass_only_refined_heldout_percent for o in outcomes]),
        "unpredictable part of B": _median([o.unrecorded_percent for o in outcomes]),
        "own physics on B": _median([o.own_physics_percent for o in outcomes]),
    }
    print(f"\nmedians over {count} rigs: " + ", ".join(f"{k} {v}" for k, v in medians.items()))
    limit = f"{LIMIT_PERCENT:.0f}%"
    counts = {
        "both rate families named": sum(o.both_named for o in outcomes),
        "both rates named closer to the truth than stated (in the final model)": sum(
            o.rates_right for o in outcomes
        ),
        "(as named at their steps)": sum(bool(o.rates_right_at_step) for o in outcomes),
        "unexplained": sum(o.unexplained for o in outcomes),
        f"doctor held-out ≤ {limit}": held_within,
        f"doctor meets item 5 (rates named, held-out ≤ {limit}, unexplained)": sum(
            o.doctor_meets for o in outcomes
        ),
        f"mass-only held-out ≤ {limit}": sum(o.mass_only_meets for o in outcomes),
        f"mass-only refined held-out ≤ {limit}": sum(
            _within(o.mass_only_refined_heldout_percent) for o in outcomes
        ),
        f"own physics held-out ≤ {limit}": sum(_within(o.own_physics_percent) for o in outcomes),
        # simulators.lab_rig has no sensor fault: a sensor family named takes up part of the unrecorded force
        "a sensor family named (the world has none)": sum(
            any(n.startswith(SENSOR_FAMILIES) for n in o.named) for o in outcomes
        ),
    }
    print("; ".join(f"{k}: {v}/{count}" for k, v in counts.items()))
    reachable = [o for o in outcomes if _within(o.unrecorded_percent)]
    doctor_met, mass_met = sum(o.doctor_meets for o in reachable), sum(o.mass_only_meets for o in reachable)
    print(
        f"rigs whose unpredictable part of B is ≤ {limit}: {len(reachable)}/{count}; on them the doctor "
        f"meets item 5 on {doctor_met}, mass-only on {mass_met}"
    )
    own = [o for o in outcomes if _within(o.own_physics_percent)]
    refined_met = sum(_within(o.mass_only_refined_heldout_percent) for o in own)
    print(
        f"rigs whose own physics (every constant right, no unrecorded force) is ≤ {limit} on B: "
        f"{len(own)}/{count}; on them the doctor meets item 5 on {sum(o.doctor_meets for o in own)}, "
        f"mass-only on {sum(o.mass_only_meets for o in own)}, mass-only refined on {refined_met}"
    )
    pairs = [
        (o.mass_only_curve_percent, o.mass_only_refined_curve_percent)
        for o in outcomes
        if o.mass_only_curve_percent is not None and o.mass_only_refined_curve_percent is not None
    ]
    if pairs:
        curves = {
            "doctor": [o.doctor_curve_percent for o in outcomes if o.doctor_curve_percent is not None],
            "identify": [plain for plain, _ in pairs],
            "identify --refine": [refined for _, refined in pairs],
        }
        print(
            "damper curve against the rig's own damper, median % of its peak: "
            + ", ".join(f"{k} {statistics.median(v):.1f}%" for k, v in curves.items() if v)
            + f"; the refined curve farther from the damper than identify's on "
            f"{sum(refined > plain for plain, refined in pairs)}/{len(pairs)} rigs"
        )
    doctor_s = [o.doctor_s for o in outcomes]
    print(f"doctor wall time per rig: median {statistics.median(doctor_s):.0f} s (max {max(doctor_s):.0f} s)")


def outcome_from_json(row: dict[str, object]) -> Outcome:
    rates = row.get("mass_only_rates_N_per_m")
    return Outcome(
        **{  # type: ignore[arg-type]
            **row,
            "named": tuple(row["named"]),  # type: ignore[arg-type]
            "mass_only_rates_N_per_m": tuple(rates) if rates else None,  # type: ignore[arg-type]
            "unrecorded_percent": row.get("unrecorded_percent"),
            "own_physics_percent": row.get("own_physics_percent"),
            "mass_only_refined_heldout_percent": row.get("mass_only_refined_heldout_percent"),
        }
    )
