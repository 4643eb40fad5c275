"""What the plate is told to do: the sine-sweep settings every exciter back end (Modbus, CAN, CiA 402)
understands, the simulators integrate and the estimator checks a recording against. Pure data with no
dependency, so every layer may import it (it lived in drivers/exciter/ before, where simulators and
daq had to reach into a driver for it)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from estimator.errors import InvalidValueError


class SweepLaw(StrEnum):
    """How the instantaneous frequency moves from start to stop."""

    LINEAR = "linear"
    LOGARITHMIC = "logarithmic"


@dataclass(frozen=True)
class SweepSettings:
    """A sine sweep of the plate: x_r(t) = amplitude_m * sin(phase(t)), frequency from start_Hz to stop_Hz.

    amplitude_m is the zero-to-peak plate displacement (the bench standard is 4 mm); duration_s is the
    sweep itself, without settling time. A logarithmic sweep needs start_Hz > 0.
    """

    start_Hz: float = 0.0
    stop_Hz: float = 20.0
    amplitude_m: float = 0.004
    duration_s: float = 20.0
    law: SweepLaw = SweepLaw.LINEAR

    def __post_init__(self) -> None:
        if self.duration_s <= 0:
            raise InvalidValueError(f"sweep duration_s must be > 0, got {self.duration_s}")
        if self.amplitude_m < 0:
            raise InvalidValueError(f"sweep amplitude_m must be >= 0, got {self.amplitude_m}")
        if self.start_Hz < 0 or self.stop_Hz < 0:
            raise InvalidValueError("sweep frequencies must be >= 0 Hz")
        if self.law is SweepLaw.LOGARITHMIC and min(self.start_Hz, self.stop_Hz) <= 0:
            raise InvalidValueError("a logarithmic sweep needs start_Hz and stop_Hz > 0")
