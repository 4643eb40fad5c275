"""The numeric codes the plate drive speaks, shared by the Modbus register map and the CAN DBC.

Both protocols carry the same vocabulary: a command code written by the host, a state code and a fault
code reported by the drive, a sweep-law code. The DBC value tables (VAL_) repeat these numbers for CAN
tools; tests check that the two agree. `ExciterStatus` is a status decoded from those codes: the driver
returns it and the simulated drive reports it, so it lives here with the codes and not in the driver's
interface (simulators may use a driver's codecs and address maps only).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum, StrEnum

from drivers.exciter.errors import ExciterDeviceFaultError, ExciterError
from estimator.sweep import SweepLaw


class ExciterState(StrEnum):
    """What the drive is doing with the plate."""

    IDLE = "idle"
    RUNNING = "running"
    STOPPING = "stopping"
    FAULT = "fault"


class CommandCode(IntEnum):
    """Command word written by the host. NONE doubles as "status request" on CAN."""

    NONE = 0
    START = 1
    STOP = 2
    EMERGENCY_STOP = 3
    RESET_FAULT = 4


class StateCode(IntEnum):
    """State word reported by the drive."""

    IDLE = 0
    RUNNING = 1
    STOPPING = 2
    FAULT = 3

    @classmethod
    def of(cls, state: ExciterState) -> StateCode:
        return cls[state.name]

    def to_state(self) -> ExciterState:
        return ExciterState[self.name]


class LawCode(IntEnum):
    """Sweep law register/signal value."""

    LINEAR = 0
    LOGARITHMIC = 1

    @classmethod
    def of(cls, law: SweepLaw) -> LawCode:
        return cls[law.name]

    def to_law(self) -> SweepLaw:
        return SweepLaw[self.name]


FAULT_NONE = 0
FAULT_WATCHDOG = 0x0010
"""The host keep-alive stopped for longer than the drive's watchdog timeout: the drive made a controlled
stop and latched this code until a RESET_FAULT command. Other codes come from the drive itself."""


@dataclass(frozen=True)
class ExciterStatus:
    """What the drive reports: state, latched fault code (0 = none), actual frequency and plate position."""

    state: ExciterState
    fault_code: int
    frequency_Hz: float
    position_m: float

    @classmethod
    def from_codes(
        cls, state_code: float, fault_code: float, frequency_Hz: float, position_m: float
    ) -> ExciterStatus:
        """Status from the numbers on the wire; an unknown state code is a protocol error."""
        try:
            state = StateCode(int(state_code)).to_state()
        except ValueError:
            raise ExciterError(f"drive reported unknown state code {state_code!r}") from None
        return cls(state, int(fault_code), float(frequency_Hz), float(position_m))

    @property
    def is_fault(self) -> bool:
        return self.state is ExciterState.FAULT

    def raise_for_fault(self) -> None:
        """Raise ExciterDeviceFaultError if the drive is in fault."""
        if self.is_fault:
            raise ExciterDeviceFaultError(self.fault_code)
