"""What the plate is told to do: the sine-sweep settings every exciter back end (Modbus, CAN, CiA 402)
understands, the simulators integrate and the estimator checks a recording against. Pure data with no
dependency, so every layer may import it (it lived in drivers/exciter/ before, where simulators and
daq had to reach into a driver for it)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import StrEnum

from estimator.declared import setting
from estimator.errors import InvalidValueError

MAX_FREQUENCY_HZ = 1000
"""Highest start or stop frequency a user may ask for (the bench envelope allows far less: 25 Hz)."""
MIN_DURATION_S = 1.0
"""A shorter sweep records nothing to identify (and a drive may refuse its START)."""
MAX_DURATION_S = 3600.0


class SweepLaw(StrEnum):
    """How the instantaneous frequency moves from start to stop."""

    LINEAR = "linear"
    LOGARITHMIC = "logarithmic"


@dataclass(frozen=True)
class SweepSettings:
    """A sine sweep of the plate: x_r(t) = amplitude_m * sin(phase(t)), frequency from start_Hz to stop_Hz.

    amplitude_m is the zero-to-peak plate displacement (the bench standard is 4 mm); duration_s is the
    sweep itself, without settling time. A logarithmic sweep needs start_Hz > 0.

    Each field is declared once with its unit, help and the range a user may give (estimator.declared):
    the API's sweep body, `shockbench sweep`'s options and the simulated drives derive theirs from it.
    Constructed in code, only what the sweep itself needs is checked (below), not that range.
    """

    start_Hz: float = setting(0.0, "sweep start", unit="Hz", ge=0, le=MAX_FREQUENCY_HZ)
    stop_Hz: float = setting(20.0, "sweep end", unit="Hz", ge=0, le=MAX_FREQUENCY_HZ)
    amplitude_m: float = setting(
        0.004, "plate amplitude, zero to peak", unit="m", ge=0, le=1, note="the bench envelope limits it"
    )
    duration_s: float = setting(
        20.0, "the sweep itself, without settling", unit="s", ge=MIN_DURATION_S, le=MAX_DURATION_S
    )
    law: SweepLaw = setting(SweepLaw.LINEAR, "linear or logarithmic")  # noqa: RUF009 (a dataclasses.field)

    def __post_init__(self) -> None:
        if self.duration_s <= 0:
            raise InvalidValueError(f"sweep duration_s must be > 0, got {self.duration_s}")
        if self.amplitude_m < 0:
            raise InvalidValueError(f"sweep amplitude_m must be >= 0, got {self.amplitude_m}")
        if self.start_Hz < 0 or self.stop_Hz < 0:
            raise InvalidValueError("sweep frequencies must be >= 0 Hz")
        if self.law is SweepLaw.LOGARITHMIC and min(self.start_Hz, self.stop_Hz) <= 0:
            raise InvalidValueError("a logarithmic sweep needs start_Hz and stop_Hz > 0")


SETTING_NAMES: tuple[str, ...] = tuple(f.name for f in fields(SweepSettings))
"""The sweep's settings by name, in order: what a drive stores, the API takes and the CLI offers."""
