"""CiA 402 back end of the plate exciter: a CANopen drive (canopen library on python-can), by SDO.

The drive runs the sweep itself in a manufacturer-specific mode of operation (why, and the vendor objects
assumed, in drivers/exciter/cia402_objects.py); the host configures it, moves the power state machine and
supervises. PlateExciter's operations map to:

    bring-up (first operation after open, again after a drive reboot or NMT stop): read 0x1000 (must be a
        CiA 402 device), NMT start, producer heartbeat 0x1017, 0x6007 = 1 (heartbeat loss -> fault),
        0x6060 = sweep mode (checked on 0x6061)
    configure_sweep  SDO writes of 0x2100:1..5 (all values range-checked before the first write)
    start            consumer heartbeat 0x1016:1 = host node + watchdog time, one host heartbeat (arms the
                     drive's watchdog), controlword shutdown -> switch on -> enable operation (each
                     transition awaited, see below), then controlword bit 4 rising edge: the sweep starts.
                     If the power-up fails, disable voltage withdraws it (watchdog off once disabled)
    stop             halt (bit 8): the amplitude ramps down; once the plate rests, disable operation
                     (SWITCHED ON); watchdog off only then. A stop that fails leaves the watchdog armed
    emergency stop   quick stop, QUICK STOP ACTIVE and the end of its ramp awaited, then disable voltage
                     (sent even if a wait failed); watchdog off once the drive reports a disabled state.
                     Sent at once (no bring-up)
    reset fault      controlword fault reset (bit 7 rising edge), when the statusword reports FAULT
    status           statusword 0x6041 (+ error code 0x603F in fault), position 0x6064, velocity 0x606C,
                     sweep frequency 0x2101
    keep-alive       the host's own NMT heartbeat (0x700 + host node), consumed by the drive (0x1016)

State transitions (drivers/exciter/cia402_sequences.py): a real drive takes 10..200 ms per transition (a
brake releasing, a contactor closing), so each one is awaited by polling the statusword, up to
`transition_timeout_s` (a ramp to rest up to `ramp_timeout_s`) on `clock`, waiting with `sleep` between
polls; a timeout is DriveStateTimeoutError naming the state the drive last reported. The drive is never
left enabled and unsupervised: the watchdog is disarmed only once the drive reports a disabled state, and
the polls of a wait feed it (they read and check the drive, as a supervision step does).

Statusword -> ExciterStatus: FAULT -> fault; FAULT REACTION ACTIVE -> stopping (with the error code); bit
12 (sweep running) -> running; bit 13 (ramping down) or the plate not yet at rest (bit 10 clear) in
OPERATION ENABLED / QUICK STOP ACTIVE -> stopping; otherwise idle.

Supervision, after every SDO transfer (frames arrive in order, so with a simulated clock the verdict is
deterministic, as on the plain CAN back end): the drive's heartbeat older than `heartbeat_timeout_s` ->
ExciterHeartbeatLostError; a boot-up message (the drive restarted, its settings are lost) or an NMT STOPPED
heartbeat -> ExciterConnectionLostError, and the next operation brings the drive up again.

Errors: SDO abort -> ExciterDeviceExceptionError (exception_code = the abort code, e.g. 0x08000022 "device
state" when the sweep is incomplete); no SDO answer -> ExciterTimeoutError; bus failure ->
ExciterConnectionLostError, and the next operation (or open()) opens a new bus. canopen is synchronous
(blocking SDO transfers, threads): every bus access runs in a worker thread, the event loop stays free.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

import can
import canopen
from canopen.sdo import SdoAbortedError, SdoCommunicationError

from drivers.exciter import cia402_objects as objects
from drivers.exciter.cia402_objects import DriveState
from drivers.exciter.cia402_sequences import (
    DEFAULT_RAMP_TIMEOUT_S,
    DEFAULT_TRANSITION_TIMEOUT_S,
    Cia402Sequences,
    DriveAccess,
)
from drivers.exciter.codes import CommandCode, ExciterState, LawCode
from drivers.exciter.envelope import SafetyEnvelope
from drivers.exciter.errors import (
    ExciterConfigError,
    ExciterConnectionLostError,
    ExciterDeviceExceptionError,
    ExciterDeviceFaultError,
    ExciterEncodingError,
    ExciterError,
    ExciterHeartbeatLostError,
    ExciterTimeoutError,
)
from drivers.exciter.interface import DEFAULT_KEEPALIVE_INTERVAL_S, ExciterStatus, PlateExciter
from estimator.sweep import SweepSettings

log = logging.getLogger(__name__)

NOTIFIER_POLL_S = 0.02
"""How often canopen's reader thread re-checks for shutdown (bounds the time close() takes)."""
DEFAULT_HOST_NODE_ID = 127
NMT_START = 0x01
NMT_STATE_BOOT_UP = 0
NMT_STATE_STOPPED = 4
NMT_STATE_OPERATIONAL = 5


class Cia402Exciter(PlateExciter):
    """Plate exciter on a CiA 402 drive, CANopen node `node_id` on python-can `interface`/`channel`.

    host_node_id: the node id of the host's heartbeat (the keep-alive the drive consumes).
    reply_timeout_s: SDO answer timeout. heartbeat_period_s: the drive's heartbeat (0x1017), supervised
    with heartbeat_timeout_s. watchdog_timeout_s: how long the drive waits for a host heartbeat while a
    sweep runs (0x1016) before its fault reaction stops the plate. transition_timeout_s: how long each
    state transition may take; ramp_timeout_s: how long a halt or quick-stop ramp may take to rest.
    sleep: how the host waits between statusword polls (asyncio.sleep; with a simulated `clock`, a sleep
    that advances it).
    """

    def __init__(
        self,
        interface: str,
        channel: str,
        *,
        node_id: int,
        host_node_id: int = DEFAULT_HOST_NODE_ID,
        bus_kwargs: dict[str, Any] | None = None,
        reply_timeout_s: float = 0.5,
        heartbeat_period_s: float = 0.1,
        heartbeat_timeout_s: float = 0.5,
        watchdog_timeout_s: float = 0.5,
        transition_timeout_s: float = DEFAULT_TRANSITION_TIMEOUT_S,
        ramp_timeout_s: float = DEFAULT_RAMP_TIMEOUT_S,
        envelope: SafetyEnvelope | None = None,
        keepalive_interval_s: float | None = DEFAULT_KEEPALIVE_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
    ) -> None:
        super().__init__(envelope=envelope, keepalive_interval_s=keepalive_interval_s, clock=clock)
        for name, value in (("node_id", node_id), ("host_node_id", host_node_id)):
            if not 1 <= value <= 127:
                raise ExciterConfigError(f"CANopen {name} must be 1..127, got {value}")
        timeouts_s = {"transition_timeout_s": transition_timeout_s, "ramp_timeout_s": ramp_timeout_s}
        for name, timeout_s in timeouts_s.items():
            if not timeout_s > 0:
                raise ExciterConfigError(f"{name} must be > 0 s, got {timeout_s}")
        if node_id == host_node_id:
            raise ExciterConfigError(f"the drive and the host cannot both be CANopen node {node_id}")
        self.interface = interface
        self.channel = channel
        self.node_id = node_id
        self.host_node_id = host_node_id
        self.bus_kwargs = dict(bus_kwargs or {})
        self.reply_timeout_s = reply_timeout_s
        self.heartbeat_period_s = heartbeat_period_s
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.watchdog_timeout_s = watchdog_timeout_s
        self.velocity_m_per_s = 0.0
        """Plate velocity (0x606C) at the last status read."""
        self.drive_nmt_state: int | None = None
        """NMT state in the drive's last heartbeat (5 operational, 4 stopped, 127 pre-operational)."""
        self._network: canopen.Network | None = None
        self._node: canopen.RemoteNode | None = None
        self._lock = asyncio.Lock()
        self._link_lock = asyncio.Lock()
        self._ready = False
        self._supervising_heartbeat = False
        self._last_heartbeat_s = 0.0
        self._boot_seen = False
        self._watchdog_armed = False
        self._last_controlword: int | None = None
        """The last controlword written since bring-up (None: unknown), for the bit 4 edge."""
        self._sequences = Cia402Sequences(
            DriveAccess(
                self.where,
                lambda supervise: self._drive_state(supervise=supervise),
                lambda what, word, supervise: self._controlword(what, word, supervise=supervise),
                lambda: self._read("read error code", objects.ERROR_CODE),
                self._feed_watchdog_while_waiting,
            ),
            clock=clock,
            sleep=sleep,
            transition_timeout_s=transition_timeout_s,
            ramp_timeout_s=ramp_timeout_s,
        )

    @property
    def where(self) -> str:
        return f"CANopen node {self.node_id} on {self.interface}/{self.channel}"

    @property
    def transition_timeout_s(self) -> float:
        """How long each state transition may take."""
        return self._sequences.transition_timeout_s

    @property
    def ramp_timeout_s(self) -> float:
        """How long a halt or quick-stop ramp may take to bring the plate to rest."""
        return self._sequences.ramp_timeout_s

    # ---- transport ----------------------------------------------------------------------------------

    async def open(self) -> None:
        """Connect to the bus (nothing is written); after a bus failure, replace the dead bus."""
        async with self._link_lock:
            if self._network is not None and self._reader_error() is None:
                return
            await self._close_transport()
            network = canopen.Network()
            network.NOTIFIER_CYCLE = NOTIFIER_POLL_S  # type: ignore[misc]
            try:
                await asyncio.to_thread(
                    network.connect, interface=self.interface, channel=self.channel, **self.bus_kwargs
                )
            except (can.CanError, OSError, ValueError) as exc:
                raise ExciterConnectionLostError(f"cannot open {self.where}: {exc}") from exc
            node = canopen.RemoteNode(self.node_id, objects.object_dictionary())
            node.sdo.RESPONSE_TIMEOUT = self.reply_timeout_s
            network.add_node(node)
            node.nmt.add_heartbeat_callback(self._on_heartbeat)
            self._network, self._node = network, node
            self._ready = False
            self._supervising_heartbeat = False

    async def _close_transport(self) -> None:
        network, self._network, self._node = self._network, None, None
        if network is not None:
            await asyncio.to_thread(_disconnect, network)

    def _reader_error(self) -> BaseException | None:
        notifier = self._network.notifier if self._network is not None else None
        return notifier.exception if notifier is not None else None

    async def _live_node(self) -> tuple[canopen.Network, canopen.RemoteNode]:
        if self._network is not None and self._reader_error() is not None:
            log.warning("CANopen reader on %s stopped (%s): reopening", self.where, self._reader_error())
            await self.open()
        if self._network is None or self._node is None:
            raise ExciterError(f"{self.where} is not open")
        return self._network, self._node

    # ---- heartbeats (canopen's reader thread) -------------------------------------------------------

    def _on_heartbeat(self, nmt_state: int) -> None:
        """canopen's NMT master hands over every heartbeat, the boot-up message (state 0) included."""
        self._last_heartbeat_s = self.clock()
        self.drive_nmt_state = nmt_state
        if nmt_state == NMT_STATE_BOOT_UP and self._ready:
            self._boot_seen = True

    # ---- SDO transfers ------------------------------------------------------------------------------

    async def _read(self, what: str, index: int, subindex: int = 0, *, supervise: bool = True) -> int:
        value = await self._transfer(what, lambda node: _variable(node, index, subindex).raw, supervise)
        assert isinstance(value, int)
        return value

    async def _write(
        self, what: str, index: int, value: int, subindex: int = 0, *, supervise: bool = True
    ) -> None:
        def write(node: canopen.RemoteNode) -> None:
            _variable(node, index, subindex).raw = value

        await self._transfer(what, write, supervise)

    async def _transfer(
        self, what: str, action: Callable[[canopen.RemoteNode], Any], supervise: bool = True
    ) -> Any:
        """One SDO transfer in a worker thread, its failures typed, then the supervision checks (unless
        `supervise` is False: a stop sequence checks once it has been sent whole)."""
        _, node = await self._live_node()
        async with self._lock:
            try:
                result = await asyncio.to_thread(action, node)
            except SdoAbortedError as exc:
                if supervise:
                    self._check_supervision(what)
                raise ExciterDeviceExceptionError(exc.code, f"{what}: refused by the drive ({exc})") from None
            except SdoCommunicationError as exc:
                if (reader_error := self._reader_error()) is not None:  # the answer may have come unheard
                    raise ExciterConnectionLostError(
                        f"{what}: CANopen reader stopped: {reader_error}"
                    ) from exc
                if supervise:
                    self._check_supervision(what)
                raise ExciterTimeoutError(f"{what}: no SDO answer from {self.where} ({exc})") from None
            except (can.CanError, OSError, RuntimeError) as exc:
                raise ExciterConnectionLostError(f"{what}: {self.where}: {exc}") from exc
            if supervise:
                self._check_supervision(what)
            return result

    async def _send(self, what: str, send: Callable[[canopen.Network, canopen.RemoteNode], None]) -> None:
        """An unanswered frame (NMT command, host heartbeat), sent from a worker thread."""
        network, node = await self._live_node()
        try:
            await asyncio.to_thread(send, network, node)
        except (can.CanError, OSError, RuntimeError) as exc:
            raise ExciterConnectionLostError(f"{what}: {self.where}: {exc}") from exc

    def _check_supervision(self, what: str) -> None:
        if self._boot_seen:
            self._boot_seen = False
            self._ready = False
            self._supervising_heartbeat = False
            raise ExciterConnectionLostError(
                f"{what}: {self.where} restarted (boot-up): its settings are lost"
            )
        if not self._supervising_heartbeat:
            return
        silent_s = self.clock() - self._last_heartbeat_s
        if silent_s > self.heartbeat_timeout_s:
            raise ExciterHeartbeatLostError(silent_s, self.heartbeat_timeout_s)
        if self.drive_nmt_state == NMT_STATE_STOPPED:
            self._ready = False
            raise ExciterConnectionLostError(f"{what}: {self.where} is NMT STOPPED")

    # ---- bring-up and the state machine -------------------------------------------------------------

    async def _ensure_ready(self) -> None:
        if self._ready:
            return
        self.drive_nmt_state = None  # unknown until its next heartbeat
        self._last_controlword = None
        await self._send("NMT start", lambda _, node: node.nmt.send_command(NMT_START))
        device_type = await self._read("read device type", objects.DEVICE_TYPE)
        if device_type & 0xFFFF != objects.CIA402_PROFILE:
            raise ExciterConfigError(f"{self.where} is not a CiA 402 drive (device type 0x{device_type:08X})")
        period_ms = round(self.heartbeat_period_s * 1000)
        await self._write("set drive heartbeat", objects.PRODUCER_HEARTBEAT_TIME, period_ms)
        self._last_heartbeat_s = self.clock()  # the drive has one heartbeat timeout to be heard
        self._supervising_heartbeat = True
        await self._write(
            "set heartbeat-loss reaction", objects.ABORT_CONNECTION_OPTION, objects.ABORT_CONNECTION_FAULT
        )
        if await self._read("read mode", objects.MODES_OF_OPERATION_DISPLAY) != objects.SINE_SWEEP_MODE:
            await self._write("set sweep mode", objects.MODES_OF_OPERATION, objects.SINE_SWEEP_MODE)
            shown = await self._read("read mode", objects.MODES_OF_OPERATION_DISPLAY)
            if shown != objects.SINE_SWEEP_MODE:
                raise ExciterConfigError(
                    f"{self.where} does not enter sweep mode {objects.SINE_SWEEP_MODE} (shows {shown})"
                )
        self._ready = True

    async def _drive_state(self, *, supervise: bool = True) -> tuple[DriveState, int]:
        statusword = await self._read("read statusword", objects.STATUSWORD, supervise=supervise)
        try:
            return DriveState.of_statusword(statusword), statusword
        except ValueError as exc:
            raise ExciterError(f"{self.where}: {exc}") from None

    async def _controlword(self, what: str, word: int, *, supervise: bool = True) -> None:
        self._last_controlword = None  # a write that fails may or may not have reached the drive
        await self._write(what, objects.CONTROLWORD, word, supervise=supervise)
        self._last_controlword = word

    async def _feed_watchdog_while_waiting(self) -> None:
        """After a statusword read showing no fault during a state-machine wait: the armed watchdog is
        fed (at most every keepalive_interval_s), so that a slow drive does not trip it mid-sequence."""
        if self._watchdog_armed:
            await self._feed_watchdog_if_due()

    # ---- PlateExciter wire side ---------------------------------------------------------------------

    async def _write_sweep(self, settings: SweepSettings) -> None:
        values = {
            objects.SWEEP_START_FREQUENCY: settings.start_Hz / objects.FREQUENCY_UNIT_Hz,
            objects.SWEEP_STOP_FREQUENCY: settings.stop_Hz / objects.FREQUENCY_UNIT_Hz,
            objects.SWEEP_AMPLITUDE: settings.amplitude_m / objects.AMPLITUDE_UNIT_m,
            objects.SWEEP_DURATION: settings.duration_s / objects.DURATION_UNIT_s,
            objects.SWEEP_LAW: float(LawCode.of(settings.law)),
        }
        record = objects.object_dictionary()[objects.SWEEP]
        raw: dict[int, int] = {}
        for subindex, value in values.items():  # every value checked before the first write
            variable = record[subindex]
            low, high = variable.min, variable.max
            if not (low <= round(value) <= high):
                raise ExciterEncodingError(
                    f"sweep {variable.name.lower()}: {round(value)} is outside {low}..{high} "
                    f"(0x{objects.SWEEP:04X}:{subindex})"
                )
            raw[subindex] = round(value)
        await self._ensure_ready()
        for subindex, value in raw.items():
            await self._write("configure sweep", objects.SWEEP, value, subindex)

    async def _send_command(self, command: CommandCode) -> None:
        # Stops: the transfers skip the supervision checks, which run once the sequence has been sent
        # whole; the watchdog is disarmed only once the drive reports a disabled state.
        if command is CommandCode.EMERGENCY_STOP:
            outcome = await self._sequences.quick_stop_then_disable()
            if outcome.state is not None and not outcome.state.enabled:
                await self._disarm_watchdog()
            if outcome.error is not None:
                raise outcome.error
            self._check_supervision("emergency stop")
            return
        await self._ensure_ready()
        if command is CommandCode.START:
            await self._start_sweep()
        elif command is CommandCode.STOP:
            state = await self._sequences.halt_then_disable()
            if state.enabled:  # cannot happen once the sequence returns; never disarm an enabled drive
                raise ExciterError(f"{self.where}: stop: the drive is still {state}")
            await self._disarm_watchdog()
            self._check_supervision("stop")
        elif command is CommandCode.RESET_FAULT:
            await self._sequences.reset_fault()
        elif command is not CommandCode.NONE:
            raise ExciterError(f"command {command.name} has no CiA 402 equivalent")

    async def _start_sweep(self) -> None:
        state, _ = await self._drive_state()
        if state in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
            raise ExciterDeviceFaultError(await self._read("read error code", objects.ERROR_CODE))
        consumer = (self.host_node_id << 16) | round(self.watchdog_timeout_s * 1000)
        await self._write("arm the drive watchdog", objects.CONSUMER_HEARTBEAT_TIME, consumer, 1)
        self._watchdog_armed = True
        await self._send_keepalive(0)  # the consumer supervises from the first heartbeat on
        try:
            await self._sequences.enable_operation()
        except ExciterError:
            await self._withdraw_power_up()
            raise
        if self._last_controlword is None or self._last_controlword & objects.CW_START_SWEEP:
            await self._controlword("start", objects.CW_ENABLE_OPERATION)  # bit 4 low: then an edge
        await self._controlword("start", objects.CW_ENABLE_OPERATION | objects.CW_START_SWEEP)

    async def _withdraw_power_up(self) -> None:
        """A power-up that failed: its enabling controlword (a level the drive may still act on) is
        replaced by disable voltage; the watchdog is disarmed only once the drive reports it disabled."""
        try:
            state = await self._sequences.disable_voltage("start failed")
            if not state.enabled:
                await self._disarm_watchdog()
        except ExciterError as exc:
            log.warning(
                "%s: power-up failed, then disabling it failed too (%s): watchdog left armed", self.where, exc
            )

    async def _disarm_watchdog(self) -> None:
        await self._write("disarm the drive watchdog", objects.CONSUMER_HEARTBEAT_TIME, 0, 1, supervise=False)
        self._watchdog_armed = False

    async def _send_keepalive(self, counter: int) -> None:
        """The host's NMT heartbeat (state operational); the drive consumes it as its watchdog feed."""
        heartbeat = (0x700 + self.host_node_id, bytes([NMT_STATE_OPERATIONAL]))
        await self._send("keep-alive", lambda network, _: network.send_message(*heartbeat))

    async def _read_status(self) -> ExciterStatus:
        await self._ensure_ready()
        state, statusword = await self._drive_state()
        error_code = 0
        if state in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE):
            error_code = await self._read("read error code", objects.ERROR_CODE)
        position = await self._read("read position", objects.POSITION_ACTUAL)
        velocity = await self._read("read velocity", objects.VELOCITY_ACTUAL)
        frequency = await self._read("read sweep frequency", objects.SWEEP_ACTUAL_FREQUENCY)
        self.velocity_m_per_s = velocity * objects.VELOCITY_UNIT_m_per_s
        return ExciterStatus(
            _exciter_state(state, statusword),
            error_code,
            frequency * objects.FREQUENCY_UNIT_Hz,
            position * objects.POSITION_UNIT_m,
        )


def _exciter_state(state: DriveState, statusword: int) -> ExciterState:
    if state is DriveState.FAULT:
        return ExciterState.FAULT
    if state is DriveState.FAULT_REACTION_ACTIVE:
        return ExciterState.STOPPING
    if statusword & objects.SW_SWEEP_RUNNING:
        return ExciterState.RUNNING
    moving = not statusword & objects.SW_TARGET_REACHED
    if statusword & objects.SW_RAMPING_DOWN or (
        moving and state in (DriveState.OPERATION_ENABLED, DriveState.QUICK_STOP_ACTIVE)
    ):
        return ExciterState.STOPPING
    return ExciterState.IDLE


def _variable(node: canopen.RemoteNode, index: int, subindex: int) -> Any:
    """The SDO variable of an object (subindex 0) or of a record's or array's member."""
    return node.sdo[index][subindex] if subindex else node.sdo[index]


def _disconnect(network: canopen.Network) -> None:
    try:
        network.disconnect()
    except (can.CanError, OSError, RuntimeError) as exc:  # a dead reader re-raises its error here
        log.info("closing a failed CANopen network: %s", exc)
