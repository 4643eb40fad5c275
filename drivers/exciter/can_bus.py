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
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
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
from drivers.exciter.sweep import SweepSettings

NOTIFIER_POLL_S = 0.02
"""How often python-can's reader thread re-checks for shutdown (bounds the time close() takes)."""


class CanExciter(PlateExciter):
    """Plate exciter on a CAN bus: `interface` and `channel` as python-can takes them
    (('virtual', 'vcan0'), ('socketcan', 'can0'), ...); extra `bus_kwargs` go to can.Bus (bitrate...)."""

    def __init__(
        self,
        interface: str,
        channel: str,
        *,
        bus_kwargs: dict[str, Any] | None = None,
        reply_timeout_s: float = 0.5,
        heartbeat_timeout_s: float = 0.5,
        dbc_path: str | Path = frames.DEFAULT_DBC_PATH,
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
        self.frames = ExciterFrames(dbc_path)
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

    # ---- transport ----------------------------------------------------------------------------------

    async def open(self) -> None:
        if self._bus is not None:
            return
        try:
            self._bus = can.Bus(interface=self.interface, channel=self.channel, **self.bus_kwargs)
        except (can.CanError, OSError, ValueError) as exc:
            where = f"{self.interface}/{self.channel}"
            raise ExciterConnectionLostError(f"cannot open CAN {where}: {exc}") from exc
        self._reader_error = None
        self._last_heartbeat_s = self.clock()  # supervision starts now: the drive has one timeout to speak
        self._notifier = can.Notifier(
            self._bus, [_Receiver(self)], timeout=NOTIFIER_POLL_S, loop=asyncio.get_running_loop()
        )

    async def _close_transport(self) -> None:
        notifier, self._notifier = self._notifier, None
        bus, self._bus = self._bus, None
        if notifier is not None:
            await asyncio.to_thread(notifier.stop)  # joins the reader thread: keep the loop free meanwhile
        if bus is not None:
            bus.shutdown()

    def _send(self, msg: can.Message) -> None:
        if self._bus is None:
            raise ExciterError(f"CAN exciter {self.interface}/{self.channel} is not open")
        if self._reader_error is not None:
            raise ExciterConnectionLostError(f"CAN reader stopped: {self._reader_error}")
        try:
            self._bus.send(msg, timeout=self.reply_timeout_s)
        except can.CanError as exc:
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
                self._send(msg)
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
        self._send(self.frames.encode(frames.HOST_KEEPALIVE, {"Counter": counter}))

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
