"""Simulated CiA 402 plate drive: a canopen LocalNode on a python-can bus ('virtual' in tests) with the
object dictionary of drivers/exciter/cia402_objects.py, its power state machine and the plate's motion.

What it does, on `bench.clock` (simulated time; nothing depends on the wall clock):

* SDO server (canopen's): reads of the statusword and actual values are computed at the moment of the
  read; writes of the controlword run the state machine (shutdown, switch on, enable operation, quick
  stop, disable voltage, fault reset; bit 4 starts the sweep, bit 8 halts it); writes out of range or in
  the wrong state are answered by an SDO abort (0x06090030 value range, 0x08000022 device state).
* NMT slave (canopen's): boot-up message, start/stop/pre-operational, reset node; while STOPPED it ignores
  SDO requests, and entering STOPPED with the operation enabled is an abort-connection event (0x6007).
* Heartbeat producer (0x1017): canopen's NMT slave, its periodic frame sent on simulated time by `tick()`.
* Heartbeat consumer (0x1016:1, the host's watchdog): armed by the first host heartbeat after it is set;
  when the host stays silent longer, the drive runs the 0x6007 reaction: fault 0x8130, the amplitude
  ramps down (FAULT REACTION ACTIVE), then FAULT.

Fault injection: go_silent() / resume() (no frame in or out), inject_drive_fault(code) (the plate trips).
"""

from __future__ import annotations

import struct
import threading
from dataclasses import dataclass

import can
import canopen
from canopen.objectdictionary import ODVariable
from canopen.sdo import SdoAbortedError

from drivers.exciter import cia402_objects as objects
from drivers.exciter.cia402_objects import DriveState
from drivers.exciter.codes import LawCode
from estimator.sweep import SweepSettings
from simulators.coupling import PlatePhysics, PlateState

DEFAULT_NODE_ID = 5
READER_POLL_S = 0.02
VELOCITY_WINDOW_S = 1e-3
"""The velocity actual value is the plate's displacement over this last interval, divided by it."""

ABORT_VALUE_RANGE = 0x06090030
ABORT_DEVICE_STATE = 0x08000022
NMT_STOP = 0x02
NMT_PRE_OPERATIONAL = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82
NMT_HEARTBEAT_BASE = 0x700

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
_POWERED = (DriveState.READY_TO_SWITCH_ON, DriveState.SWITCHED_ON, DriveState.OPERATION_ENABLED)


class SimulatedCia402Exciter:
    """A CiA 402 plate drive, node `node_id` on python-can `interface`/`channel`. Use `with` (or
    start()/close()); call tick() or advance() as simulated time passes."""

    def __init__(
        self,
        bench: PlatePhysics,
        *,
        channel: str,
        interface: str = "virtual",
        node_id: int = DEFAULT_NODE_ID,
    ) -> None:
        self.bench = bench
        self.clock = bench.clock
        self.channel = channel
        self.interface = interface
        self.network = _SimulatedTimeNetwork(self)
        self.node = canopen.LocalNode(node_id, objects.object_dictionary())
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        self.controlwords: list[int] = []
        """Every controlword written, in order (for tests)."""
        self.host_heartbeats_received = 0
        self.silent = False
        self._lock = threading.RLock()
        self._state = DriveState.SWITCH_ON_DISABLED
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
            self._state = DriveState.SWITCH_ON_DISABLED
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
                self.controlwords.append(value)
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
        state = self._state
        if state in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
            rising_reset = word & objects.CW_FAULT_RESET and not previous & objects.CW_FAULT_RESET
            if state is DriveState.FAULT and rising_reset:
                self._fault_reset()
            return
        if word & objects.CW_FAULT_RESET:
            return  # a fault reset outside FAULT does nothing
        command = word & 0x0F
        if not command & 0x02:  # disable voltage: power stage off, plate held by its brake
            self._power_off(DriveState.SWITCH_ON_DISABLED)
        elif command & 0x06 == 0x02:  # quick stop
            if state is DriveState.OPERATION_ENABLED:
                self.bench.stop(emergency=True)
                self._state = DriveState.QUICK_STOP_ACTIVE
            elif state in (DriveState.READY_TO_SWITCH_ON, DriveState.SWITCHED_ON):
                self._state = DriveState.SWITCH_ON_DISABLED
        elif command & 0x07 == 0x06:  # shutdown
            if state in (DriveState.SWITCH_ON_DISABLED, DriveState.SWITCHED_ON, DriveState.OPERATION_ENABLED):
                self._power_off(DriveState.READY_TO_SWITCH_ON)
        elif command == 0x07:  # switch on (from OPERATION ENABLED: disable operation)
            if state is DriveState.READY_TO_SWITCH_ON:
                self._state = DriveState.SWITCHED_ON
            elif state is DriveState.OPERATION_ENABLED:
                self._power_off(DriveState.SWITCHED_ON)
        elif command == 0x0F:  # enable operation
            if state in (DriveState.SWITCHED_ON, DriveState.QUICK_STOP_ACTIVE):
                self._state = DriveState.OPERATION_ENABLED
            if self._state is DriveState.OPERATION_ENABLED:
                self._operate(word, previous)

    def _operate(self, word: int, previous: int) -> None:
        """Bits 4 and 8 in OPERATION ENABLED: start the sweep on a rising edge of 4, halt on 8."""
        if word & objects.CW_HALT:
            self.bench.stop(emergency=False)
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

    def _power_off(self, new_state: DriveState) -> None:
        if self._state is DriveState.OPERATION_ENABLED:
            self.bench.stop(emergency=True)
        self._state = new_state

    def _fault_reset(self) -> None:
        plate = getattr(self.bench, "plate", None)
        if plate is not None and hasattr(plate, "reset_fault"):
            plate.reset_fault()
        self._error_code = 0
        self._state = DriveState.SWITCH_ON_DISABLED

    def _enter_fault(self, code: int) -> None:
        self._error_code = code
        self._state = DriveState.FAULT_REACTION_ACTIVE if self._sweep_moving() else DriveState.FAULT

    def _abort_connection(self, code: int) -> None:
        """The 0x6007 reaction (1: fault): the amplitude ramps down, then FAULT."""
        if self.node.sdo[objects.ABORT_CONNECTION_OPTION].raw != objects.ABORT_CONNECTION_FAULT:
            return
        self.bench.stop(emergency=False)
        self._enter_fault(code)

    def _cycle(self) -> None:
        """Cyclic checks (lock held): host heartbeat, plate trips, end of a fault reaction."""
        consumer = self._consumer
        now = self.clock.now_s()
        if consumer.last_s is not None and now - consumer.last_s > consumer.timeout_s:
            consumer.last_s = None  # CiA 301: supervision resumes with the next heartbeat received
            if self._state not in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
                self._abort_connection(objects.ERROR_HEARTBEAT)
        plate = self.bench.plate_status()
        if plate.state is PlateState.FAULT and self._state is not DriveState.FAULT:
            self._error_code = plate.fault_code
            self._state = DriveState.FAULT
        elif self._state is DriveState.FAULT_REACTION_ACTIVE and plate.state is PlateState.IDLE:
            self._state = DriveState.FAULT

    def _sweep_moving(self) -> bool:
        return self.bench.plate_status().state in (PlateState.RUNNING, PlateState.STOPPING)

    def _statusword(self) -> int:
        word = self._state.state_bits | objects.SW_REMOTE
        if self._state in _POWERED or self._state is DriveState.QUICK_STOP_ACTIVE:
            word |= objects.SW_VOLTAGE_ENABLED
        plate = self.bench.plate_status().state
        if plate is PlateState.RUNNING:
            word |= objects.SW_SWEEP_RUNNING
        elif plate is PlateState.STOPPING:
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


class _SimulatedTimeNetwork(canopen.Network):
    """canopen's Network for the simulated drive: periodic frames (the NMT heartbeat) go out on simulated
    time from tick(), not from a python-can timer thread; a silent drive neither sends nor hears; SDO
    requests are ignored while the node is NMT STOPPED."""

    def __init__(self, drive: SimulatedCia402Exciter) -> None:
        super().__init__()
        self.NOTIFIER_CYCLE = READER_POLL_S  # close() waits at most this long for the reader thread
        self._drive = drive
        self._periodic: list[_SimulatedPeriodicTask] = []
        self._periodic_lock = threading.Lock()
        self._host_node: int | None = None
        self.periodic_frames_sent = 0
        self.frames_ignored = 0
        """Frames heard while silent (tests wait on it to know a request reached the drive)."""

    def send_periodic(  # type: ignore[override]
        self, can_id: int, data: bytes, period: float, remote: bool = False
    ) -> _SimulatedPeriodicTask:
        task = _SimulatedPeriodicTask(self, can_id, bytes(data), period, self._drive.clock.now_s())
        with self._periodic_lock:
            self._periodic.append(task)
        task.send_due(self._drive.clock.now_s())  # python-can sends the first one at once too
        return task

    def remove_periodic(self, task: _SimulatedPeriodicTask) -> None:
        with self._periodic_lock:
            if task in self._periodic:
                self._periodic.remove(task)

    def send_due_periodic(self, now_s: float) -> None:
        with self._periodic_lock:
            tasks = list(self._periodic)
        for task in tasks:
            task.send_due(now_s)

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        if not self._drive.silent:
            super().send_message(can_id, data, remote)

    def send_periodic_frame(self, can_id: int, data: bytes) -> None:
        """One frame of a periodic task; a silent drive skips it (no backlog once it speaks again)."""
        if self._drive.silent:
            return
        try:
            super().send_message(can_id, data)
        except (can.CanError, RuntimeError):
            return  # bus closing under the tick
        self.periodic_frames_sent += 1

    def notify(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self._drive.silent:
            self.frames_ignored += 1
            return
        if can_id == self._drive.node.sdo.rx_cobid and self._drive.node.nmt.state == "STOPPED":
            return
        super().notify(can_id, data, timestamp)

    def subscribe_host(self, host_node: int | None) -> None:
        """Hear the heartbeat of `host_node` (None: of nobody)."""
        self.unsubscribe_host()
        if host_node is not None:
            self._host_node = host_node
            self.subscribe(NMT_HEARTBEAT_BASE + host_node, self._drive.on_host_heartbeat)

    def unsubscribe_host(self) -> None:
        if self._host_node is not None:
            self.unsubscribe(NMT_HEARTBEAT_BASE + self._host_node, self._drive.on_host_heartbeat)
            self._host_node = None


class _SimulatedPeriodicTask:
    """What canopen's NMT slave expects of a periodic task (stop, update), run on simulated time."""

    def __init__(
        self, network: _SimulatedTimeNetwork, can_id: int, data: bytes, period_s: float, now_s: float
    ) -> None:
        self.network = network
        self.can_id = can_id
        self.data = data
        self.period_s = period_s
        self.next_s = now_s
        self._lock = threading.Lock()

    def stop(self) -> None:
        self.network.remove_periodic(self)

    def update(self, data: bytes) -> None:
        self.data = bytes(data)

    def send_due(self, now_s: float) -> None:
        with self._lock:
            due = 0
            while self.next_s <= now_s + 1e-12:
                self.next_s += self.period_s
                due += 1
        if due:  # one frame however many periods passed: a late tick does not send a backlog
            self.network.send_periodic_frame(self.can_id, self.data)
