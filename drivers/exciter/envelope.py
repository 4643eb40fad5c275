"""The safety envelope: the sweeps a plate exciter driver is allowed to send.

Two layers of limits:

* hard limits — what the plate may ever do on this installation (mechanical rating); they come from the
  installation, not from a bench recipe;
* bench limits — what one bench configuration allows (4 mm, 25 Hz, 300 s by default); a bench may lower
  them, never raise them above the hard limits (`ExciterConfigError` naming the field and the hard limit).
  The duration is the one default below its hard limit (3600 s): a soak or endurance bench may lengthen it.

Every back end checks a sweep with `SafetyEnvelope.check` before anything goes on the wire, so a refused
sweep leaves the drive untouched. While the sweep runs, each status the drive reports is checked with
`SafetyEnvelope.breach` (frequency and plate position within the limits plus `REPORTED_MARGIN`; still
running `OVERRUN_MARGIN_S` past the sweep's end is a breach too); the driver answers a breach with an
emergency stop (drivers/exciter/interface.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields

from drivers.exciter.errors import EnvelopeViolationError, ExciterConfigError
from estimator.sweep import SweepSettings


@dataclass(frozen=True)
class EnvelopeLimits:
    """Upper bounds of a sweep: zero-to-peak plate amplitude, any frequency of the sweep, and its duration.

    max_duration_s bounds how long the plate may be told to move in one sweep (a unit mistake once wrote
    an 11-day sweep to a drive); 300 s is five times the slowest sweep the method needs."""

    max_amplitude_m: float = 0.004
    max_frequency_Hz: float = 25.0
    max_duration_s: float = 300.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ExciterConfigError(f"envelope limit {f.name} must be finite and > 0, got {value!r}")

    @classmethod
    def from_mapping(cls, values: Mapping[str, object]) -> EnvelopeLimits:
        """Limits from a config table (e.g. a TOML [envelope] section); unknown keys are an error."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ExciterConfigError(f"unknown envelope key(s) {unknown}; expected some of {sorted(known)}")
        return cls(**values)  # type: ignore[arg-type]


DEFAULT_HARD_LIMITS = EnvelopeLimits(max_duration_s=3600.0)
"""Installation hard limits when none are configured: the plate's rated ±4 mm and 25 Hz, sweeps of at
most an hour (a bench allows 300 s unless its configuration says more)."""

REPORTED_MARGIN = 0.05
"""A reported frequency or position may exceed its limit by this fraction of it (measurement noise,
control overshoot) before it is a breach."""
OVERRUN_MARGIN_S = 1.0
"""A drive still reporting RUNNING this long after the sweep's end (host clock) is in breach."""


class SafetyEnvelope:
    """Bench limits, validated against the hard limits at construction, and the sweep check."""

    def __init__(
        self, limits: EnvelopeLimits | None = None, hard_limits: EnvelopeLimits = DEFAULT_HARD_LIMITS
    ) -> None:
        limits = limits or EnvelopeLimits(
            min(EnvelopeLimits.max_amplitude_m, hard_limits.max_amplitude_m),
            min(EnvelopeLimits.max_frequency_Hz, hard_limits.max_frequency_Hz),
            min(EnvelopeLimits.max_duration_s, hard_limits.max_duration_s),
        )
        for f in fields(EnvelopeLimits):
            bench, hard = getattr(limits, f.name), getattr(hard_limits, f.name)
            if bench > hard:
                raise ExciterConfigError(
                    f"bench envelope {f.name}={bench!r} is above the hard limit {f.name}={hard!r}"
                )
        self.limits = limits
        self.hard_limits = hard_limits

    def check(self, settings: SweepSettings) -> None:
        """Raise EnvelopeViolationError (naming the sweep field and the limit) unless the sweep is inside."""
        lim = self.limits
        checks = (
            ("amplitude_m", settings.amplitude_m, "max_amplitude_m", lim.max_amplitude_m),
            ("start_Hz", settings.start_Hz, "max_frequency_Hz", lim.max_frequency_Hz),
            ("stop_Hz", settings.stop_Hz, "max_frequency_Hz", lim.max_frequency_Hz),
            ("duration_s", settings.duration_s, "max_duration_s", lim.max_duration_s),
        )
        for field_name, value, limit_name, limit in checks:
            if not (math.isfinite(value) and value <= limit):  # NaN and inf are outside too
                raise EnvelopeViolationError(field_name, value, limit_name, limit)

    def breach(
        self, frequency_Hz: float, position_m: float, running_for_s: float | None, duration_s: float | None
    ) -> tuple[str, float, str, float] | None:
        """What a drive reported while moving, against the limits: None if inside, else (quantity, value,
        limit name, limit) of the first breach. running_for_s: host seconds since the start, given only
        while the drive reports RUNNING; duration_s: the sweep's."""
        lim = self.limits
        reported = (
            ("frequency_Hz", frequency_Hz, "max_frequency_Hz", lim.max_frequency_Hz),
            ("position_m", abs(position_m), "max_amplitude_m", lim.max_amplitude_m),
        )
        for quantity, value, limit_name, limit in reported:
            if not (math.isfinite(value) and value <= limit * (1.0 + REPORTED_MARGIN)):
                return quantity, value, limit_name, limit
        if running_for_s is None or duration_s is None:
            return None
        if running_for_s > duration_s + OVERRUN_MARGIN_S:
            return "running_s", running_for_s, "sweep duration_s", duration_s
        return None

    def __repr__(self) -> str:
        return f"SafetyEnvelope(limits={self.limits!r}, hard_limits={self.hard_limits!r})"
