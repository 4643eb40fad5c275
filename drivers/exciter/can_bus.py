"""CAN back end of the plate exciter: python-can bus, frames from exciter.dbc through cantools.

Request/answer: every host frame but the keep-alive carries a Sequence number and is answered by one
EXC_Status echoing it (Result says whether the request was accepted). The drive also sends EXC_Heartbeat
periodically; the driver supervises it on the injectable `clock`.

Supervision is evaluated after each exchange (answer received or reply timeout). The bus delivers frames
in order, so by the time the answer has been handled every heartbeat and error frame sent before it has
been handled too: with a simulated clock the verdict is deterministic. After an exchange:

* heartbeat older than `heartbeat_timeout_s` -> ExciterHeartbeatLostError (also when the answer timed out);
* an error frame was seen since the last exchange -> ExciterBusError (reported once);
* Result REJECTED_FAULT -> ExciterDeviceFaultError, other rejections -> ExciterDeviceExceptionError.

Frame ids: the DBC's (0x680..0x689, clear of CANopen's predefined connection set) or moved to `base_id`
(can_frames.ExciterFrames).

Sending never blocks the event loop: python-can's `send` may wait for room in the transmit queue (up to
`reply_timeout_s`), so frames go out from one sender thread, in the order they were sent.

Reader failure: when python-can's reader thread stops on an error (interface gone, socket closed), the
request waiting for an answer fails with ExciterConnectionLostError, and the next operation (or open())
shuts the dead bus down and opens a new one, as the Modbus back end reconnects. Heartbeat supervision
restarts with the new bus (the drive has one heartbeat timeout to be heard again).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import can

from drivers.exciter import can_frames as frames
from drivers.exciter.can_frames import CanResult, ExciterFrames, Signals
from drivers.exciter.codes import CommandCode, LawCode
from drivers.exciter.envelope import SafetyEnvelope
from drivers.exciter.errors import (
    ExciterBusError,
    ExciterConnectionLostError,
    ExciterDeviceExceptionError,
    ExciterDeviceFaultError,
    ExciterError,
    ExciterHeartbeatLostError,
    ExciterTimeoutError,
)
from drivers.exciter.interface import DEFAULT_KEEPALIVE_INTERVAL_S, ExciterStatus, PlateExciter
from estimator.sweep import SweepSettings

log = logging.getLogger(__name__)

NOTIFIER_POLL_S = 0.02
"""How often python-can's reader thread re-checks for shutdown (bounds the time close() takes)."""


class CanExciter(PlateExciter):
    """Plate exciter on a CAN bus: `interface` and `channel` as python-can takes them
    (('virtual', 'vcan0'), ('socketcan', 'can0'), ...); extra `bus_kwargs` go to can.Bus (bitrate...).
    base_id: first id of the frame set (None: the DBC's, 0x680); the simulated drive must use the same."""

    def __init__(
        self,
        interface: str,
        channel: str,
        *,
        bus_kwargs: dict[str, Any] | None = None,
        reply_timeout_s: float = 0.5,
        heartbeat_timeout_s: float = 0.5,
        dbc_path: str | Path = frames.DEFAULT_DBC_PATH,
        base_id: int | None = None,
        envelope: SafetyEnvelope | None = None,
        keepalive_interval_s: float | None = DEFAULT_KEEPALIVE_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(envelope=envelope, keepalive_interval_s=keepalive_interval_s, clock=clock)
        self.interface = interface
        self.channel = channel
        self.bus_kwargs = dict(bus_kwargs or {})
        self.reply_timeout_s = reply_timeout_s
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.frames = ExciterFrames(dbc_path, base_id=base_id)
        self.heartbeat_counter: int | None = None
        """Counter of the last drive heartbeat received (None before the first one)."""
        self._bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self._lock = asyncio.Lock()
        self._sequence = 0
        self._pending: tuple[int, asyncio.Future[Signals]] | None = None
        self._last_heartbeat_s = 0.0
        self._bus_error = False
        self._reader_error: Exception | None = None
        self._sender: ThreadPoolExecutor | None = None
        self._link_lock = asyncio.Lock()

    # ---- transport ----------------------------------------------------------------------------------

    async def open(self) -> None:
        """Open the bus; after a reader error, shut the dead bus down first and open a new one."""
        async with self._link_lock:
            if self._bus is not None and self._reader_error is None:
                return
            await self._close_transport()
            self._open_bus()

    def _make_bus(self) -> can.BusABC:
        """The python-can bus (a seam for tests that need a bus with special behaviour)."""
        return can.Bus(interface=self.interface, channel=self.channel, **self.bus_kwargs)

    def _open_bus(self) -> None:
        try:
            bus = self._make_bus()
        except (can.CanError, OSError, ValueError) as exc:
            where = f"{self.interface}/{self.channel}"
            raise ExciterConnectionLostError(f"cannot open CAN {where}: {exc}") from exc
        self._bus = bus
        self._reader_error = None
        self._bus_error = False
        self._last_heartbeat_s = self.clock()  # supervision starts now: the drive has one timeout to speak
        self._sender = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"can-send {self.channel}")
        self._notifier = can.Notifier(
            bus, [_Receiver(self)], timeout=NOTIFIER_POLL_S, loop=asyncio.get_running_loop()
        )

    async def _close_transport(self) -> None:
        notifier, self._notifier = self._notifier, None
        bus, self._bus = self._bus, None
        sender, self._sender = self._sender, None
        if notifier is not None:
            await asyncio.to_thread(notifier.stop)  # joins the reader thread: keep the loop free meanwhile
        if sender is not None:
            sender.shutdown(wait=False, cancel_futures=True)  # a send under way ends by its own timeout
        if bus is not None:
            bus.shutdown()

    async def _live_bus(self) -> tuple[can.BusABC, ThreadPoolExecutor]:
        """The open bus; a bus whose reader died is replaced first (the next operation reconnects)."""
        if self._reader_error is not None:
            log.warning(
                "CAN reader on %s/%s stopped (%s): reopening",
                self.interface,
                self.channel,
                self._reader_error,
            )
            await self.open()
        if self._bus is None or self._sender is None:
            raise ExciterError(f"CAN exciter {self.interface}/{self.channel} is not open")
        return self._bus, self._sender

    async def _send(self, msg: can.Message) -> None:
        """Queue one frame on the sender thread and wait for python-can to take it, loop kept free."""
        bus, sender = await self._live_bus()
        try:
            await asyncio.get_running_loop().run_in_executor(sender, bus.send, msg, self.reply_timeout_s)
        except (can.CanError, OSError, RuntimeError) as exc:  # RuntimeError: sender shut down by close()
            where = f"{self.interface}/{self.channel}"
            raise ExciterConnectionLostError(f"CAN send on {where} failed: {exc}") from exc

    # ---- receiving (called in the event loop by the python-can Notifier) ----------------------------

    def _on_frame(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            self._bus_error = True
            return
        decoded = self.frames.decode(msg)
        if decoded is None:
            return
        name, signals = decoded
        if name == frames.HEARTBEAT:
            self._last_heartbeat_s = self.clock()
            self.heartbeat_counter = int(signals["Counter"])
        elif name == frames.STATUS and self._pending is not None:
            sequence, future = self._pending
            if int(signals["Sequence"]) == sequence and not future.done():
                future.set_result(signals)

    def _on_reader_error(self, exc: Exception) -> None:
        self._reader_error = exc
        if self._pending is not None and not self._pending[1].done():
            self._pending[1].set_exception(ExciterConnectionLostError(f"CAN reader stopped: {exc}"))

    # ---- request / answer ---------------------------------------------------------------------------

    async def _exchange(self, what: str, frame_name: str, signals: Signals) -> Signals:
        """Send one host frame (Sequence added), wait for its EXC_Status, then run the supervision checks."""
        async with self._lock:
            self._sequence = (self._sequence + 1) & 0xFF
            msg = self.frames.encode(frame_name, {**signals, "Sequence": self._sequence})
            future: asyncio.Future[Signals] = asyncio.get_running_loop().create_future()
            self._pending = (self._sequence, future)
            try:
                await self._send(msg)
                answer = await asyncio.wait_for(future, self.reply_timeout_s)
            except TimeoutError:
                self._check_supervision(what)
                raise ExciterTimeoutError(
                    f"{what}: no answer from the drive within {self.reply_timeout_s} s"
                ) from None
            finally:
                self._pending = None
            self._check_supervision(what)
        result = int(answer["Result"])
        if result == CanResult.REJECTED_FAULT:
            raise ExciterDeviceFaultError(int(answer["FaultCode"]), f"{what} refused: plate drive in fault")
        if result != CanResult.OK:
            name = CanResult(result).name if result in CanResult._value2member_map_ else str(result)
            raise ExciterDeviceExceptionError(result, f"{what} refused by the drive ({name})")
        return answer

    def _check_supervision(self, what: str) -> None:
        silent_s = self.clock() - self._last_heartbeat_s
        if silent_s > self.heartbeat_timeout_s:
            raise ExciterHeartbeatLostError(silent_s, self.heartbeat_timeout_s)
        if self._bus_error:
            self._bus_error = False
            raise ExciterBusError(f"{what}: CAN error frame on {self.interface}/{self.channel}")

    # ---- PlateExciter wire side ---------------------------------------------------------------------

    async def _write_sweep(self, settings: SweepSettings) -> None:
        # Encode both halves before sending either: a value out of range leaves the drive untouched.
        first = {
            "StartFrequency": settings.start_Hz,
            "StopFrequency": settings.stop_Hz,
            "Law": LawCode.of(settings.law),
        }
        second = {"Amplitude": settings.amplitude_m, "Duration": settings.duration_s}
        self.frames.encode(frames.SWEEP_FREQUENCIES, {**first, "Sequence": 0})
        self.frames.encode(frames.SWEEP_SHAPE, {**second, "Sequence": 0})
        await self._exchange("configure sweep", frames.SWEEP_FREQUENCIES, first)
        await self._exchange("configure sweep", frames.SWEEP_SHAPE, second)

    async def _send_command(self, command: CommandCode) -> None:
        await self._exchange(f"command {command.name}", frames.COMMAND, {"Command": command})

    async def _send_keepalive(self, counter: int) -> None:
        await self._send(self.frames.encode(frames.HOST_KEEPALIVE, {"Counter": counter}))

    async def _read_status(self) -> ExciterStatus:
        answer = await self._exchange("read status", frames.COMMAND, {"Command": CommandCode.NONE})
        return ExciterStatus.from_codes(
            answer["State"], answer["FaultCode"], answer["ActualFrequency"], answer["ActualPosition"]
        )


class _Receiver(can.Listener):
    """Hands frames and reader-thread errors to the exciter (in its event loop, via can.Notifier)."""

    def __init__(self, exciter: CanExciter) -> None:
        self._exciter = exciter

    def on_message_received(self, msg: can.Message) -> None:
        self._exciter._on_frame(msg)

    def on_error(self, exc: Exception) -> None:
        self._exciter._on_reader_error(exc)
