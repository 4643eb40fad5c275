"""Simulated CiA 402 plate drive: a canopen LocalNode on a python-can bus ('virtual' in tests) with the
object dictionary of drivers/exciter/cia402_objects.py, its power state machine and the plate's motion.

What it does, on `bench.clock` (simulated time; nothing depends on the wall clock):

* SDO server (canopen's): reads of the statusword and actual values are computed at the moment of the
  read; writes of the controlword run the state machine (shutdown, switch on, enable operation, disable
  operation, quick stop, disable voltage, fault reset; bit 4 starts the sweep, bit 8 halts it); writes out
  of range or in the wrong state are answered by an SDO abort (0x06090030 value range, 0x08000022 device
  state).
* Transition times, as a real drive's (a brake releasing, a contactor closing): each commanded transition
  takes `transition_s` (per target state: `transition_s_to`); the statusword shows the old state until
  then. The controlword is a level: the same word written again leaves the transition under way alone, a
  different one replaces it.
* Ramps: halt (bit 8) ramps the plate down (the plate's own controlled stop, cut at `halt_ramp_s` if
  given); a quick stop ramps it down for `quick_stop_ramp_s`, then, per the quick stop option code 0x605A,
  goes to SWITCH ON DISABLED (1..4) or stays in QUICK STOP ACTIVE at rest (5..8); 0 disables at once.
  Statusword bit 13 while a ramp runs, bit 10 once the plate rests. Disabling the power stage during a
  ramp halts the plate at once and counts in `ramps_cut_short`.
* NMT slave (canopen's): boot-up message, start/stop/pre-operational, reset node; while STOPPED it ignores
  SDO requests, and entering STOPPED with the operation enabled is an abort-connection event (0x6007).
* Heartbeat producer (0x1017): canopen's NMT slave, its periodic frame sent on simulated time by `tick()`.
* Heartbeat consumer (0x1016:1, the host's watchdog): armed by the first host heartbeat after it is set;
  when the host stays silent longer, the drive runs the 0x6007 reaction: fault 0x8130, the amplitude
  ramps down (FAULT REACTION ACTIVE), then FAULT.

Fault injection: go_silent() / resume() (no frame in or out), inject_drive_fault(code) (the plate trips).
Records, for tests: `received` (every controlword with the time, state and statusword it found) and
`timeline` (every state entered, with its time).
"""

from __future__ import annotations

import struct
import threading
from collections.abc import Mapping
from dataclasses import dataclass

import canopen
from canopen.objectdictionary import ODVariable
from canopen.sdo import SdoAbortedError

from drivers.exciter import cia402_objects as objects
from drivers.exciter.cia402_objects import DriveState
from drivers.exciter.codes import LawCode
from estimator.sweep import SweepSettings
from simulators.coupling import PlatePhysics, PlateState
from simulators.devices.canopen_sim_network import SimulatedTimeNetwork
from simulators.devices.cia402_state_machine import (
    POWERED,
    PendingTransition,
    Ramp,
    ReceivedControlword,
    commanded_state,
)

DEFAULT_NODE_ID = 5
VELOCITY_WINDOW_S = 1e-3
"""The velocity actual value is the plate's displacement over this last interval, divided by it."""

ABORT_VALUE_RANGE = 0x06090030
ABORT_DEVICE_STATE = 0x08000022
NMT_STOP = 0x02
NMT_PRE_OPERATIONAL = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82

_SWEEP_FIELDS = {
    objects.SWEEP_START_FREQUENCY: "start_Hz",
    objects.SWEEP_STOP_FREQUENCY: "stop_Hz",
    objects.SWEEP_AMPLITUDE: "amplitude_m",
    objects.SWEEP_DURATION: "duration_s",
    objects.SWEEP_LAW: "law",
}
_SWEEP_UNITS = {
    objects.SWEEP_START_FREQUENCY: objects.FREQUENCY_UNIT_Hz,
    objects.SWEEP_STOP_FREQUENCY: objects.FREQUENCY_UNIT_Hz,
    objects.SWEEP_AMPLITUDE: objects.AMPLITUDE_UNIT_m,
    objects.SWEEP_DURATION: objects.DURATION_UNIT_s,
    objects.SWEEP_LAW: 1.0,
}


class SimulatedCia402Exciter:
    """A CiA 402 plate drive, node `node_id` on python-can `interface`/`channel`. Use `with` (or
    start()/close()); call tick() or advance() as simulated time passes.

    transition_s: how long each commanded state transition takes (0: at once); transition_s_to: per
    target state, overriding it. quick_stop_ramp_s: the quick stop's ramp. halt_ramp_s: the halt's ramp
    (None: the plate's own controlled stop).
    """

    def __init__(
        self,
        bench: PlatePhysics,
        *,
        channel: str,
        interface: str = "virtual",
        node_id: int = DEFAULT_NODE_ID,
        transition_s: float = 0.0,
        transition_s_to: Mapping[DriveState, float] | None = None,
        quick_stop_ramp_s: float = 0.1,
        halt_ramp_s: float | None = None,
    ) -> None:
        self.bench = bench
        self.clock = bench.clock
        self.channel = channel
        self.interface = interface
        self.network = SimulatedTimeNetwork(self)
        self.node = canopen.LocalNode(node_id, objects.object_dictionary())
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        self.transition_s = transition_s
        self.transition_s_to = dict(transition_s_to or {})
        self.quick_stop_ramp_s = quick_stop_ramp_s
        self.halt_ramp_s = halt_ramp_s
        self.received: list[ReceivedControlword] = []
        """Every controlword written, in order, with what the drive was when it came (for tests)."""
        self.timeline: list[tuple[float, DriveState]] = [(self.clock.now_s(), DriveState.SWITCH_ON_DISABLED)]
        """Every state entered, with its time (for tests)."""
        self.ramps_cut_short = 0
        self.host_heartbeats_received = 0
        self.silent = False
        self._lock = threading.RLock()
        self._state = DriveState.SWITCH_ON_DISABLED
        self._pending: PendingTransition | None = None
        self._ramp: Ramp | None = None
        self._controlword = 0
        self._mode = 0
        self._error_code = 0
        self._sweep: dict[str, float] = {}
        self._consumer = _Consumer()

    # ---- lifecycle ----------------------------------------------------------------------------------

    def start(self) -> None:
        """Connect, send the boot-up message and enter PRE-OPERATIONAL."""
        self.network.connect(interface=self.interface, channel=self.channel)
        self.network.add_node(self.node)
        self.network.subscribe(0, self._on_nmt)  # after the node's own NMT handler: sees the new state
        self._boot()

    def close(self) -> None:
        self.network.disconnect()

    def __enter__(self) -> SimulatedCia402Exciter:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ---- time ---------------------------------------------------------------------------------------

    def tick(self) -> None:
        """The drive's cyclic work at clock.now_s(): heartbeat supervision, state updates, heartbeats due."""
        with self._lock:
            self._cycle()
        self.network.send_due_periodic(self.clock.now_s())

    def advance(self, dt_s: float) -> None:
        self.clock.advance(dt_s)
        self.tick()

    # ---- what tests look at -------------------------------------------------------------------------

    @property
    def state(self) -> DriveState:
        with self._lock:
            self._cycle()
            return self._state

    @property
    def controlwords(self) -> list[int]:
        """Every controlword written, in order."""
        return [received.word for received in self.received]

    @property
    def heartbeats_sent(self) -> int:
        """Heartbeat frames the drive has sent (boot-up message not counted)."""
        return self.network.periodic_frames_sent

    @property
    def nmt_state(self) -> str:
        return self.node.nmt.state

    @property
    def error_code(self) -> int:
        return self._error_code

    # ---- fault injection ----------------------------------------------------------------------------

    def go_silent(self) -> None:
        self.silent = True

    def resume(self) -> None:
        self.silent = False

    def inject_drive_fault(self, code: int) -> None:
        """The drive trips with error code `code` (the plate halts at once) until a fault reset."""
        plate = getattr(self.bench, "plate", None)
        if plate is None or not hasattr(plate, "set_fault"):
            raise TypeError("drive fault injection needs a bench with a SimulatedPlate as .plate")
        with self._lock:
            plate.set_fault(code)
            self._enter_fault(code)

    # ---- NMT ----------------------------------------------------------------------------------------

    def _boot(self) -> None:
        self.node.nmt.send_command(NMT_RESET_NODE)  # INITIALISING: the boot-up message
        self.node.nmt.send_command(NMT_PRE_OPERATIONAL)  # heartbeat producer from 0x1017 (0 = off)

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        command, node_id = struct.unpack_from("BB", data)
        if node_id not in (0, self.node.id):
            return
        if command in (NMT_RESET_NODE, NMT_RESET_COMMUNICATION):
            self._reset()
        elif command == NMT_STOP:
            with self._lock:
                if self._state is DriveState.OPERATION_ENABLED:
                    self._abort_connection(objects.ERROR_NMT_STOPPED)

    def _reset(self) -> None:
        """Reset node: the power stage goes off (plate halted), every setting back to its default."""
        with self._lock:
            self.bench.stop(emergency=True)
            self.node.data_store.clear()
            self._pending = self._ramp = None
            self._set_state(DriveState.SWITCH_ON_DISABLED)
            self._controlword = 0
            self._mode = 0
            self._sweep = {}
            self._consumer = _Consumer()
            self.network.unsubscribe_host()
        self.node.nmt.stop_heartbeat()
        self._boot()

    # ---- SDO object access (canopen SDO server, python-can reader thread) ---------------------------

    def _on_read(self, index: int, subindex: int, od: object) -> int | None:
        with self._lock:
            self._cycle()
            if index == objects.STATUSWORD:
                return self._statusword()
            if index == objects.ERROR_CODE:
                return self._error_code
            if index == objects.MODES_OF_OPERATION_DISPLAY:
                return self._mode
            if index == objects.POSITION_ACTUAL:
                return round(self.bench.position_m("x_r") / objects.POSITION_UNIT_m)
            if index == objects.VELOCITY_ACTUAL:
                return round(self._velocity_m_per_s() / objects.VELOCITY_UNIT_m_per_s)
            if index == objects.SWEEP_ACTUAL_FREQUENCY:
                return round(self.bench.plate_status().frequency_Hz / objects.FREQUENCY_UNIT_Hz)
            return None  # stored value or default

    def _on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        value = od.decode_raw(data)
        assert isinstance(value, int)
        if (od.min is not None and value < od.min) or (od.max is not None and value > od.max):
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        with self._lock:
            self._cycle()
            if index == objects.CONTROLWORD:
                now = self.clock.now_s()
                self.received.append(ReceivedControlword(now, value, self._state, self._statusword()))
                self._on_controlword(value)
            elif index == objects.MODES_OF_OPERATION:
                if value not in (0, objects.SINE_SWEEP_MODE):
                    raise SdoAbortedError(ABORT_VALUE_RANGE)
                if self._sweep_moving():
                    raise SdoAbortedError(ABORT_DEVICE_STATE)
                self._mode = value
            elif index == objects.SWEEP:
                self._sweep[_SWEEP_FIELDS[subindex]] = value * _SWEEP_UNITS[subindex]
            elif index == objects.CONSUMER_HEARTBEAT_TIME and subindex == 1:
                self._consumer = _Consumer(host_node=(value >> 16) & 0x7F, timeout_s=(value & 0xFFFF) / 1000)
                self.network.subscribe_host(self._consumer.host_node if self._consumer.timeout_s else None)

    def on_host_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """A heartbeat of the consumed host node (python-can reader thread)."""
        with self._lock:
            self._cycle()  # a heartbeat that comes too late does not undo the trip
            self.host_heartbeats_received += 1
            if self._consumer.timeout_s:
                self._consumer.last_s = self.clock.now_s()

    # ---- the state machine --------------------------------------------------------------------------

    def _on_controlword(self, word: int) -> None:
        previous, self._controlword = self._controlword, word
        if self._pending is not None and word == previous:
            return  # the same level again: the transition under way goes on
        self._pending = None
        state = self._state
        if state in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
            rising_reset = word & objects.CW_FAULT_RESET and not previous & objects.CW_FAULT_RESET
            if state is DriveState.FAULT and rising_reset:
                self._begin(DriveState.SWITCH_ON_DISABLED, word)
            return
        if word & objects.CW_FAULT_RESET:
            return  # a fault reset outside FAULT does nothing
        target = commanded_state(state, word & 0x0F)
        if target is not None:
            self._begin(target, word)
        elif state is DriveState.OPERATION_ENABLED and word & 0x0F == 0x0F:
            self._operate(word, previous)

    def _begin(self, target: DriveState, word: int) -> None:
        """Start a commanded transition: at once, or after its transition time."""
        duration_s = self.transition_s_to.get(target, self.transition_s)
        if duration_s <= 0:
            self._enter(target)
        else:
            self._pending = PendingTransition(word, target, self.clock.now_s() + duration_s)

    def _enter(self, target: DriveState) -> None:
        """A commanded transition completes, with its effect on the power stage and the plate."""
        previous = self._state
        if previous is DriveState.FAULT:
            self._fault_reset()
        elif not target.enabled and previous.enabled:
            self._halt_power_stage()
        self._set_state(target)
        if target is DriveState.QUICK_STOP_ACTIVE:
            self._start_quick_stop()

    def _start_quick_stop(self) -> None:
        option = self._stored(objects.QUICK_STOP_OPTION)
        if option == 0:  # disable the drive function at once
            self._halt_power_stage()
            self._set_state(DriveState.SWITCH_ON_DISABLED)
            return
        then = DriveState.SWITCH_ON_DISABLED if option <= 4 else None
        now = self.clock.now_s()
        if self._sweep_moving():
            self.bench.stop(emergency=False)
            self._ramp = Ramp(now + self.quick_stop_ramp_s, then)
        else:
            self._ramp = Ramp(now, then)
        self._end_ramp_if_due(now)

    def _end_ramp_if_due(self, now: float) -> None:
        ramp = self._ramp
        if ramp is None or now < ramp.end_s:
            return
        self._ramp = None
        self.bench.stop(emergency=True)  # the plate rests where the ramp has brought it
        if ramp.then is not None and self._state is DriveState.QUICK_STOP_ACTIVE:
            self._set_state(ramp.then)

    def _halt_power_stage(self) -> None:
        """The power stage goes off: the plate halts at once (held by its brake), a ramp is cut short."""
        if self._ramp is not None:
            self.ramps_cut_short += 1
            self._ramp = None
        self.bench.stop(emergency=True)

    def _set_state(self, state: DriveState) -> None:
        if state is not self._state:
            self.timeline.append((self.clock.now_s(), state))
        self._state = state

    def _stored(self, index: int) -> int:
        """An object's value as stored (or its default), without the read callbacks."""
        variable = self.node.object_dictionary[index]
        assert isinstance(variable, ODVariable)
        data = self.node.data_store.get(index, {}).get(0)
        value = variable.decode_raw(data) if data is not None else variable.default
        assert isinstance(value, int)
        return value

    def _operate(self, word: int, previous: int) -> None:
        """Bits 4 and 8 in OPERATION ENABLED: start the sweep on a rising edge of 4, halt on 8."""
        if word & objects.CW_HALT:
            if self._sweep_moving() and self._ramp is None:
                self.bench.stop(emergency=False)
                if self.halt_ramp_s is not None:
                    self._ramp = Ramp(self.clock.now_s() + self.halt_ramp_s)
            return
        if not (word & objects.CW_START_SWEEP and not previous & objects.CW_START_SWEEP):
            return
        if self._mode != objects.SINE_SWEEP_MODE or set(self._sweep) != set(_SWEEP_FIELDS.values()):
            raise SdoAbortedError(ABORT_DEVICE_STATE)  # not in sweep mode, or the sweep is incomplete
        try:
            settings = SweepSettings(
                start_Hz=self._sweep["start_Hz"],
                stop_Hz=self._sweep["stop_Hz"],
                amplitude_m=self._sweep["amplitude_m"],
                duration_s=self._sweep["duration_s"],
                law=LawCode(round(self._sweep["law"])).to_law(),
            )
            self.bench.start_sweep(settings)
        except (ValueError, RuntimeError) as exc:  # settings the drive cannot run, plate in fault
            raise SdoAbortedError(ABORT_VALUE_RANGE) from exc

    def _fault_reset(self) -> None:
        plate = getattr(self.bench, "plate", None)
        if plate is not None and hasattr(plate, "reset_fault"):
            plate.reset_fault()
        self._error_code = 0

    def _enter_fault(self, code: int) -> None:
        self._error_code = code
        self._pending = self._ramp = None
        self._set_state(DriveState.FAULT_REACTION_ACTIVE if self._sweep_moving() else DriveState.FAULT)

    def _abort_connection(self, code: int) -> None:
        """The 0x6007 reaction (1: fault): the amplitude ramps down, then FAULT."""
        if self._stored(objects.ABORT_CONNECTION_OPTION) != objects.ABORT_CONNECTION_FAULT:
            return
        self.bench.stop(emergency=False)
        self._enter_fault(code)

    def _cycle(self) -> None:
        """Cyclic checks (lock held): transitions and ramps due, host heartbeat, plate trips, end of a
        fault reaction."""
        consumer = self._consumer
        now = self.clock.now_s()
        pending = self._pending
        if pending is not None and now >= pending.due_s:
            self._pending = None
            self._enter(pending.target)
        self._end_ramp_if_due(now)
        if consumer.last_s is not None and now - consumer.last_s > consumer.timeout_s:
            consumer.last_s = None  # CiA 301: supervision resumes with the next heartbeat received
            if self._state not in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
                self._abort_connection(objects.ERROR_HEARTBEAT)
        plate = self.bench.plate_status()
        if plate.state is PlateState.FAULT and self._state is not DriveState.FAULT:
            self._error_code = plate.fault_code
            self._pending = self._ramp = None
            self._set_state(DriveState.FAULT)
        elif self._state is DriveState.FAULT_REACTION_ACTIVE and plate.state is PlateState.IDLE:
            self._set_state(DriveState.FAULT)

    def _sweep_moving(self) -> bool:
        return self.bench.plate_status().state in (PlateState.RUNNING, PlateState.STOPPING)

    def _statusword(self) -> int:
        word = self._state.state_bits | objects.SW_REMOTE
        if self._state in POWERED or self._state is DriveState.QUICK_STOP_ACTIVE:
            word |= objects.SW_VOLTAGE_ENABLED
        plate = self.bench.plate_status().state
        if plate is PlateState.RUNNING:
            word |= objects.SW_SWEEP_RUNNING
        elif plate is PlateState.STOPPING or self._ramp is not None:
            word |= objects.SW_RAMPING_DOWN
        else:
            word |= objects.SW_TARGET_REACHED
        return word

    def _velocity_m_per_s(self) -> float:
        now = self.clock.now_s()
        before = self.bench.position_m("x_r", now - VELOCITY_WINDOW_S)
        return (self.bench.position_m("x_r", now) - before) / VELOCITY_WINDOW_S


@dataclass
class _Consumer:
    """The drive's consumer heartbeat entry 0x1016:1 and its supervision state."""

    host_node: int = 0
    timeout_s: float = 0.0
    last_s: float | None = None
    """Time of the last host heartbeat; None: not supervising (none received since set or since a trip)."""
