"""The CiA 402 power state machine of the simulated drive (simulators/devices/cia402_exciter.py): which
state a controlword command leads to, and the records of transitions under way, ramps and received
controlwords."""

from __future__ import annotations

from dataclasses import dataclass

from drivers.exciter.cia402_objects import DriveState

POWERED = (DriveState.READY_TO_SWITCH_ON, DriveState.SWITCHED_ON, DriveState.OPERATION_ENABLED)
"""The states with the voltage applied (statusword bit 4) besides QUICK STOP ACTIVE."""
_DISABLE_VOLTAGE_FROM = (*POWERED, DriveState.QUICK_STOP_ACTIVE)


@dataclass(frozen=True)
class ReceivedControlword:
    """One controlword write as the drive received it: when, the word, and what the drive was then."""

    time_s: float
    word: int
    state: DriveState
    statusword: int


@dataclass(frozen=True)
class PendingTransition:
    """A commanded transition under way."""

    word: int
    target: DriveState
    due_s: float


@dataclass(frozen=True)
class Ramp:
    """A halt or quick-stop ramp under way: the plate halts at `end_s` if still moving, then the drive
    enters `then` (None: stays where it is)."""

    end_s: float
    then: DriveState | None = None


def commanded_state(state: DriveState, command: int) -> DriveState | None:
    """The state the controlword command bits (0..3) lead to from `state` (CiA 402 transitions), None
    for no transition."""
    if not command & 0x02:  # disable voltage: transitions 7, 9, 10, 12
        return DriveState.SWITCH_ON_DISABLED if state in _DISABLE_VOLTAGE_FROM else None
    if command & 0x06 == 0x02:  # quick stop: 11, and 7/10 from the states without a running drive
        if state is DriveState.OPERATION_ENABLED:
            return DriveState.QUICK_STOP_ACTIVE
        return DriveState.SWITCH_ON_DISABLED if state in POWERED else None
    if command & 0x07 == 0x06:  # shutdown: 2, 6, 8
        shutdown_from = (DriveState.SWITCH_ON_DISABLED, DriveState.SWITCHED_ON, DriveState.OPERATION_ENABLED)
        return DriveState.READY_TO_SWITCH_ON if state in shutdown_from else None
    if command == 0x07:  # switch on: 3; disable operation: 5
        switch_on_from = (DriveState.READY_TO_SWITCH_ON, DriveState.OPERATION_ENABLED)
        return DriveState.SWITCHED_ON if state in switch_on_from else None
    if command == 0x0F:  # enable operation: 4, 16
        enable_from = (DriveState.SWITCHED_ON, DriveState.QUICK_STOP_ACTIVE)
        return DriveState.OPERATION_ENABLED if state in enable_from else None
    return None
