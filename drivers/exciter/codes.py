"""The numeric codes the plate drive speaks, shared by the Modbus register map and the CAN DBC.

Both protocols carry the same vocabulary: a command code written by the host, a state code and a fault
code reported by the drive, a sweep-law code. The DBC value tables (VAL_) repeat these numbers for CAN
tools; tests check that the two agree.
"""

from __future__ import annotations

from enum import IntEnum, StrEnum

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
