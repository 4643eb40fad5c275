"""Simulated plate drive on a python-can bus (the 'virtual' interface in tests) speaking exciter.dbc.

Host frames are answered at once from python-can's reader thread (EXC_Status echoing the Sequence);
EXC_Heartbeat goes out every `heartbeat_period_s` of *simulated* time: `tick()` emits whatever is due at
clock.now_s(), `advance(dt_s)` moves the clock and ticks. Nothing depends on the wall clock, so tests
are deterministic.

Fault injection:
    go_silent() / resume()    the drive stops sending (heartbeats and answers) and ignores the host
    inject_error_frame()      an error frame on the bus
    inject_drive_fault(code)  the drive trips (SimulatedPlate.set_fault) and reports `code`
"""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path

import can

from drivers.exciter import can_frames as frames
from drivers.exciter.can_frames import CanResult, ExciterFrames, Signals
from drivers.exciter.codes import StateCode
from simulators.coupling import PlatePhysics
from simulators.devices.exciter import (
    DEFAULT_WATCHDOG_TIMEOUT_S,
    ExciterRefusalError,
    RefusalReason,
    SimulatedExciter,
)

DEFAULT_HEARTBEAT_PERIOD_S = 0.1
READER_POLL_S = 0.02
"""How often the reader thread re-checks for shutdown (bounds the time close() takes)."""

_RESULT_FOR = {
    RefusalReason.FAULT: CanResult.REJECTED_FAULT,
    RefusalReason.NOT_CONFIGURED: CanResult.NOT_CONFIGURED,
    RefusalReason.INVALID_VALUE: CanResult.INVALID_VALUE,
}


class SimulatedCanExciter:
    """A plate drive on CAN `channel` of python-can `interface`. Use `with` (or start()/close()).
    base_id moves the frame set as the driver's does (None: the DBC's ids)."""

    def __init__(
        self,
        bench: PlatePhysics,
        *,
        channel: str,
        interface: str = "virtual",
        heartbeat_period_s: float = DEFAULT_HEARTBEAT_PERIOD_S,
        watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
        dbc_path: str | Path = frames.DEFAULT_DBC_PATH,
        base_id: int | None = None,
    ) -> None:
        self.exciter = SimulatedExciter(bench, watchdog_timeout_s)
        self.clock = bench.clock
        self.channel = channel
        self.interface = interface
        self.heartbeat_period_s = heartbeat_period_s
        self.frames = ExciterFrames(dbc_path, base_id=base_id)
        self.received: list[tuple[str, Signals]] = []
        """Every host frame seen on the bus (also while silent), decoded, in arrival order."""
        self.heartbeats_sent = 0
        self.silent = False
        self._lock = threading.RLock()
        self._next_heartbeat_s = self.clock.now_s()
        self._bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None

    # ---- lifecycle ----------------------------------------------------------------------------------

    def start(self) -> None:
        self._bus = can.Bus(interface=self.interface, channel=self.channel)
        self._notifier = can.Notifier(self._bus, [self._on_frame], timeout=READER_POLL_S)

    def close(self) -> None:
        if self._notifier is not None:
            self._notifier.stop()
            self._notifier = None
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def __enter__(self) -> SimulatedCanExciter:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ---- time ---------------------------------------------------------------------------------------

    def tick(self) -> None:
        """Run the drive's checks and send the heartbeats due at the current simulated time."""
        with self._lock:
            self.exciter.tick()
            now = self.clock.now_s()
            while self._next_heartbeat_s <= now:
                self._next_heartbeat_s += self.heartbeat_period_s
                if not self.silent:  # a silent drive skips its heartbeats, it does not queue them
                    state = StateCode.of(self.exciter.status().state)
                    self._send(frames.HEARTBEAT, {"Counter": self.heartbeats_sent & 0xFF, "State": state})
                    self.heartbeats_sent += 1

    def advance(self, dt_s: float) -> None:
        """Advance the simulated clock by dt_s, then tick."""
        self.clock.advance(dt_s)
        self.tick()

    async def run(self, period_s: float = 0.01) -> None:
        """Tick forever (for a drive served on a wall-clock SimulatedClock)."""
        while True:
            self.tick()
            await asyncio.sleep(period_s)

    # ---- fault injection ----------------------------------------------------------------------------

    def go_silent(self) -> None:
        with self._lock:
            self.silent = True

    def resume(self) -> None:
        with self._lock:
            self.silent = False

    def inject_error_frame(self) -> None:
        assert self._bus is not None, "start() first"
        self._bus.send(can.Message(is_error_frame=True, is_extended_id=False))

    def inject_drive_fault(self, code: int) -> None:
        self.exciter.inject_fault(code)

    # ---- host frames (python-can reader thread) -----------------------------------------------------

    def _on_frame(self, msg: can.Message) -> None:
        decoded = self.frames.decode(msg)
        if decoded is None:
            return
        name, signals = decoded
        with self._lock:
            self.received.append((name, signals))
            if self.silent:
                return
            if name == frames.HOST_KEEPALIVE:
                self.exciter.keepalive(int(signals["Counter"]))
                return
            if name not in (frames.COMMAND, frames.SWEEP_FREQUENCIES, frames.SWEEP_SHAPE):
                return  # drive -> host frames of another node, or ours echoed
            result = CanResult.OK
            try:
                self._handle_request(name, signals)
            except ExciterRefusalError as refusal:
                result = _RESULT_FOR[refusal.reason]
            self._answer(int(signals["Sequence"]), result)

    def _handle_request(self, name: str, signals: Signals) -> None:
        if name == frames.COMMAND:
            self.exciter.tick()
            if int(signals["Command"]):
                self.exciter.command(int(signals["Command"]))
        elif name == frames.SWEEP_FREQUENCIES:
            self.exciter.set_sweep_params(
                start_Hz=signals["StartFrequency"], stop_Hz=signals["StopFrequency"], law=signals["Law"]
            )
        else:
            self.exciter.set_sweep_params(amplitude_m=signals["Amplitude"], duration_s=signals["Duration"])

    def _answer(self, sequence: int, result: CanResult) -> None:
        status = self.exciter.status()
        self._send(
            frames.STATUS,
            {
                "State": StateCode.of(status.state),
                "Result": result,
                "Sequence": sequence,
                "FaultCode": status.fault_code,
                "ActualFrequency": status.frequency_Hz,
                "ActualPosition": status.position_m,
            },
        )

    def _send(self, name: str, signals: Signals) -> None:
        if self._bus is not None:
            self._bus.send(self.frames.encode(name, signals))
