"""The object dictionary of a CiA 402 plate drive, as the host back end (drivers/exciter/cia402.py) and the
simulated drive (simulators/devices/cia402_exciter.py) both use it, built in code with canopen's classes.

Standard objects (CiA 301 communication, CiA 402 drive profile):

    0x1000 device type (low word 402 = the drive profile)   0x1016:1 consumer heartbeat time (host watchdog)
    0x1017 producer heartbeat time (ms)                      0x6007 abort connection option code
    0x603F error code                                        0x6040 controlword / 0x6041 statusword
    0x6060 modes of operation / 0x6061 display               0x6064 position actual value
    0x606C velocity actual value                             0x605A quick stop option code

Documented assumptions (what a drive must offer to run a plate sweep; a real drive's EDS maps its own
vendor objects onto these, or the indices here are changed):

* Mode of operation SINE_SWEEP_MODE (-16, in the manufacturer-specific range -128..-1 of 0x6060): the
  drive generates the sine sweep itself. A chirp up to 20 Hz cannot be fed point by point over the bus
  (profile position moves are far too slow; a cyclic synchronous position mode would need the host to send
  set-points at 1 kHz with real-time jitter, and a host hiccup would become a plate jerk), so the host
  configures the sweep once and supervises it.
* 0x2100 "sine sweep" record, written by SDO before the start: 1 start frequency (mHz), 2 stop frequency
  (mHz), 3 amplitude zero-to-peak (µm), 4 duration (ms), 5 law (0 linear, 1 logarithmic).
* 0x2101 actual sweep frequency (mHz, read only).
* Controlword bit 4 (operation-mode specific, as "new set-point" in profile position mode): its rising
  edge in OPERATION ENABLED starts the configured sweep; bit 8 (halt) ramps the amplitude down to rest
  (halt option code 0x605D = 1).
* Statusword bit 12 (operation-mode specific): sweep running at full amplitude; bit 13: amplitude ramping
  down (halt, end of sweep or fault reaction); bit 10 (target reached): plate at rest.
* User units: position 1 µm, velocity 1 µm/s (the drive's factor group set accordingly).
"""

from __future__ import annotations

from enum import StrEnum

from canopen import ObjectDictionary
from canopen.objectdictionary import ODArray, ODRecord, ODVariable, datatypes
from canopen.profiles.p402 import State402

DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
CONSUMER_HEARTBEAT_TIME = 0x1016
PRODUCER_HEARTBEAT_TIME = 0x1017
ABORT_CONNECTION_OPTION = 0x6007
ERROR_CODE = 0x603F
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
QUICK_STOP_OPTION = 0x605A
HALT_OPTION = 0x605D
MODES_OF_OPERATION = 0x6060
MODES_OF_OPERATION_DISPLAY = 0x6061
POSITION_ACTUAL = 0x6064
VELOCITY_ACTUAL = 0x606C
SWEEP = 0x2100
SWEEP_ACTUAL_FREQUENCY = 0x2101

SWEEP_START_FREQUENCY = 1
SWEEP_STOP_FREQUENCY = 2
SWEEP_AMPLITUDE = 3
SWEEP_DURATION = 4
SWEEP_LAW = 5

CIA402_PROFILE = 402
DEVICE_TYPE_SERVO = 0x0002_0000 | CIA402_PROFILE
"""0x1000 of a CiA 402 servo drive: additional information 0x0002 (servo), profile 402."""

SINE_SWEEP_MODE = -16
"""Manufacturer-specific mode of operation (0x6060): the drive runs the sweep of 0x2100 itself."""

ABORT_CONNECTION_FAULT = 1
"""0x6007 value: heartbeat loss (or NMT stopped) -> fault, with the fault reaction (a ramp down)."""

QUICK_STOP_RAMP_THEN_DISABLED = 2
"""0x605A value (CiA 402 default): a quick stop ramps the plate down, then SWITCH ON DISABLED. Values 1..4
end in SWITCH ON DISABLED, 5..8 stay in QUICK STOP ACTIVE at rest, 0 disables the drive at once."""
QUICK_STOP_RAMP_THEN_STAY = 6
"""0x605A value: a quick stop ramps the plate down and the drive stays in QUICK STOP ACTIVE."""

FREQUENCY_UNIT_Hz = 1e-3
AMPLITUDE_UNIT_m = 1e-6
DURATION_UNIT_s = 1e-3
POSITION_UNIT_m = 1e-6
VELOCITY_UNIT_m_per_s = 1e-6

# Controlword (0x6040) commands from canopen's CiA 402 profile, plus the bits of this drive.
CW_DISABLE_VOLTAGE = State402.CW_DISABLE_VOLTAGE
CW_QUICK_STOP = State402.CW_QUICK_STOP
CW_SHUTDOWN = State402.CW_SHUTDOWN
CW_SWITCH_ON = State402.CW_SWITCH_ON
CW_ENABLE_OPERATION = State402.CW_OPERATION_ENABLED
CW_FAULT_RESET = 0x0080
CW_START_SWEEP = 0x0010
CW_HALT = 0x0100

# Statusword (0x6041) bits beyond the state bits.
SW_VOLTAGE_ENABLED = 0x0010
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
SW_SWEEP_RUNNING = 0x1000
SW_RAMPING_DOWN = 0x2000

ERROR_HEARTBEAT = 0x8130
"""0x603F after the host's heartbeat stopped (CiA 301 emergency code: life guard or heartbeat error)."""
ERROR_NMT_STOPPED = 0x8100
"""0x603F after an NMT stop while the operation was enabled (CiA 301: communication, generic)."""


class DriveState(StrEnum):
    """The CiA 402 power state machine, named as canopen's State402 names them."""

    NOT_READY_TO_SWITCH_ON = "NOT READY TO SWITCH ON"
    SWITCH_ON_DISABLED = "SWITCH ON DISABLED"
    READY_TO_SWITCH_ON = "READY TO SWITCH ON"
    SWITCHED_ON = "SWITCHED ON"
    OPERATION_ENABLED = "OPERATION ENABLED"
    QUICK_STOP_ACTIVE = "QUICK STOP ACTIVE"
    FAULT_REACTION_ACTIVE = "FAULT REACTION ACTIVE"
    FAULT = "FAULT"

    @classmethod
    def of_statusword(cls, statusword: int) -> DriveState:
        """The state a statusword reports (canopen's State402.SW_MASK table)."""
        for name, (mask, value) in State402.SW_MASK.items():
            if statusword & mask == value:
                return cls(name)
        raise ValueError(f"statusword 0x{statusword:04X} reports no CiA 402 state")

    @property
    def enabled(self) -> bool:
        """The drive function is (or may be) on: the power stage can move the plate. Every other state
        is disabled (no torque; the plate held by its brake or at rest)."""
        return self in (
            DriveState.OPERATION_ENABLED,
            DriveState.QUICK_STOP_ACTIVE,
            DriveState.FAULT_REACTION_ACTIVE,
        )

    @property
    def state_bits(self) -> int:
        """The statusword bits that encode this state (the `value` of its SW_MASK entry)."""
        return State402.SW_MASK[self.value][1]


def plate_at_rest(statusword: int) -> bool:
    """The statusword says the plate rests: target reached (bit 10), neither running (12) nor ramping (13)."""
    return bool(statusword & SW_TARGET_REACHED) and not statusword & (SW_SWEEP_RUNNING | SW_RAMPING_DOWN)


def object_dictionary() -> ObjectDictionary:
    """The drive's objects, with types, access, defaults and value ranges (the ranges are what the host
    checks before writing and the simulated drive enforces)."""
    od = ObjectDictionary()
    od.add_object(_variable("Device type", DEVICE_TYPE, datatypes.UNSIGNED32, "ro", DEVICE_TYPE_SERVO))
    od.add_object(_variable("Error register", ERROR_REGISTER, datatypes.UNSIGNED8, "ro", 0))
    consumer = ODArray("Consumer heartbeat time", CONSUMER_HEARTBEAT_TIME)
    consumer.add_member(_variable("Number of entries", CONSUMER_HEARTBEAT_TIME, datatypes.UNSIGNED8, "ro", 1))
    consumer.add_member(
        _variable("Consumer heartbeat time 1", CONSUMER_HEARTBEAT_TIME, datatypes.UNSIGNED32, "rw", 0, sub=1)
    )
    od.add_object(consumer)
    od.add_object(
        _variable("Producer heartbeat time", PRODUCER_HEARTBEAT_TIME, datatypes.UNSIGNED16, "rw", 0)
    )
    od.add_object(
        _variable(
            "Abort connection option code",
            ABORT_CONNECTION_OPTION,
            datatypes.INTEGER16,
            "rw",
            1,
            low=0,
            high=1,
        )
    )
    od.add_object(_variable("Error code", ERROR_CODE, datatypes.UNSIGNED16, "ro", 0))
    od.add_object(_variable("Controlword", CONTROLWORD, datatypes.UNSIGNED16, "rw", 0))
    od.add_object(_variable("Statusword", STATUSWORD, datatypes.UNSIGNED16, "ro", 0))
    od.add_object(
        _variable(
            "Quick stop option code",
            QUICK_STOP_OPTION,
            datatypes.INTEGER16,
            "rw",
            QUICK_STOP_RAMP_THEN_DISABLED,
            low=0,
            high=8,
        )
    )
    od.add_object(_variable("Halt option code", HALT_OPTION, datatypes.INTEGER16, "rw", 1, low=1, high=1))
    od.add_object(_variable("Modes of operation", MODES_OF_OPERATION, datatypes.INTEGER8, "rw", 0))
    od.add_object(
        _variable("Modes of operation display", MODES_OF_OPERATION_DISPLAY, datatypes.INTEGER8, "ro", 0)
    )
    od.add_object(_variable("Position actual value", POSITION_ACTUAL, datatypes.INTEGER32, "ro", 0))
    od.add_object(_variable("Velocity actual value", VELOCITY_ACTUAL, datatypes.INTEGER32, "ro", 0))
    sweep = ODRecord("Sine sweep", SWEEP)
    sweep.add_member(_variable("Highest sub-index supported", SWEEP, datatypes.UNSIGNED8, "ro", 5))
    for sub, name, high in (
        (SWEEP_START_FREQUENCY, "Start frequency", 100_000),  # mHz: 100 Hz
        (SWEEP_STOP_FREQUENCY, "Stop frequency", 100_000),
        (SWEEP_AMPLITUDE, "Amplitude", 20_000),  # µm: 20 mm, the plate's stroke
        (SWEEP_DURATION, "Duration", 3_600_000),  # ms: one hour
    ):
        sweep.add_member(_variable(name, SWEEP, datatypes.UNSIGNED32, "rw", None, sub=sub, low=0, high=high))
    sweep.add_member(_variable("Law", SWEEP, datatypes.UNSIGNED8, "rw", None, sub=SWEEP_LAW, low=0, high=1))
    od.add_object(sweep)
    od.add_object(_variable("Sweep actual frequency", SWEEP_ACTUAL_FREQUENCY, datatypes.UNSIGNED32, "ro", 0))
    return od


def _variable(
    name: str,
    index: int,
    data_type: int,
    access: str,
    default: int | None,
    *,
    sub: int = 0,
    low: int | None = None,
    high: int | None = None,
) -> ODVariable:
    variable = ODVariable(name, index, sub)
    variable.data_type = data_type
    variable.access_type = access
    variable.default = default
    variable.min = low
    variable.max = high
    return variable
