"""One asyncio interface for every plate exciter back end (Modbus TCP/RTU, CAN).

`PlateExciter` holds what every back end shares, so it exists once:

* the safety envelope, checked before anything is sent;
* the host keep-alive that feeds the drive's watchdog while a sweep runs (from start() until stop(),
  emergency_stop() or close(); a drive that is not running ignores it): sent by a background task
  every `keepalive_interval_s`, and also ahead of any operation once it is due. "Due" is measured on
  the injectable `clock` (time.monotonic by default; a SimulatedClock's now_s in tests, which makes
  the keep-alive traffic deterministic);
* the start/stop bookkeeping (a start needs a configured sweep and a drive not in fault).

A back end implements the wire side only: `open`, `_write_sweep`, `_send_command`, `_send_keepalive`,
`_read_status`, `_close_transport`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

from drivers.exciter.codes import CommandCode, ExciterState, StateCode
from drivers.exciter.envelope import SafetyEnvelope
from drivers.exciter.errors import ExciterDeviceFaultError, ExciterError
from drivers.exciter.sweep import SweepSettings

__all__ = ["ExciterState", "ExciterStatus", "PlateExciter"]

log = logging.getLogger(__name__)

DEFAULT_KEEPALIVE_INTERVAL_S = 0.1
"""Host keep-alive period; drives are expected to trip their watchdog after several missed periods."""


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


class PlateExciter(ABC):
    """A plate drive controller: configure a sweep, start, stop (controlled), emergency stop, status.

    Use as `async with exciter:` (open/close) or call `open()` / `close()`. Closing does not stop the
    plate: a host that goes away mid-sweep leaves the drive's watchdog to stop it.

    envelope: the sweeps allowed (default: SafetyEnvelope(), 4 mm / 25 Hz).
    keepalive_interval_s: keep-alive period while a sweep runs; None sends none by itself (the caller
        then calls keep_alive()).
    clock: seconds, for "is a keep-alive due" (and, on CAN, the heartbeat supervision).
    """

    def __init__(
        self,
        *,
        envelope: SafetyEnvelope | None = None,
        keepalive_interval_s: float | None = DEFAULT_KEEPALIVE_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.envelope = envelope or SafetyEnvelope()
        self.keepalive_interval_s = keepalive_interval_s
        self.clock = clock
        self.keepalive_error: ExciterError | None = None
        """Last error of the background keep-alive (it keeps trying); None after a successful send."""
        self._sweep: SweepSettings | None = None
        self._running = False
        self._keepalive_counter = 0
        self._last_keepalive_s = 0.0
        self._keepalive_task: asyncio.Task[None] | None = None

    # ---- public interface -------------------------------------------------------------------------

    @abstractmethod
    async def open(self) -> None:
        """Connect to the drive (the transport only: nothing is written)."""

    async def configure_sweep(self, settings: SweepSettings) -> None:
        """Check the sweep against the envelope, then write it to the drive (it does not start)."""
        self.envelope.check(settings)
        await self._feed_watchdog_if_due()
        await self._write_sweep(settings)
        self._sweep = settings

    async def start(self) -> None:
        """Start the configured sweep. Refused (ExciterDeviceFaultError) if the drive is in fault."""
        if self._sweep is None:
            raise ExciterError("no sweep configured: call configure_sweep first")
        self.envelope.check(self._sweep)  # the envelope object may have been replaced since configure
        (await self.status()).raise_for_fault()
        await self._send_command(CommandCode.START)
        self._running = True
        self._last_keepalive_s = self.clock()
        self._start_keepalive_task()

    async def stop(self) -> None:
        """Controlled stop: the drive ramps the amplitude down, then the plate rests.

        The keep-alive ends first, whatever the outcome: should the stop command be lost, the drive's
        watchdog stops the plate anyway."""
        self._stop_supervision()
        await self._send_command(CommandCode.STOP)

    async def emergency_stop(self) -> None:
        """Immediate stop: sent at once, without any preliminary traffic (keep-alive ends as for stop)."""
        self._stop_supervision()
        await self._send_command(CommandCode.EMERGENCY_STOP)

    async def reset_fault(self) -> None:
        """Acknowledge a latched drive fault (watchdog, drive trip) so the drive accepts START again."""
        await self._send_command(CommandCode.RESET_FAULT)

    async def status(self) -> ExciterStatus:
        """Read the drive status. A drive in fault is reported here, not raised (see raise_for_fault)."""
        await self._feed_watchdog_if_due()
        return await self._read_status()

    async def keep_alive(self) -> None:
        """Send one keep-alive now (the background task and every operation do so when it is due)."""
        self._keepalive_counter = (self._keepalive_counter + 1) & 0xFF
        await self._send_keepalive(self._keepalive_counter)
        self._last_keepalive_s = self.clock()

    async def close(self) -> None:
        """Stop the keep-alive and release the transport. Idempotent."""
        task = self._keepalive_task
        self._stop_supervision()
        if task is not None:
            await asyncio.gather(task, return_exceptions=True)  # let the cancelled task finish
        await self._close_transport()

    async def __aenter__(self) -> PlateExciter:
        await self.open()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    @property
    def sweep(self) -> SweepSettings | None:
        """The last sweep written to the drive."""
        return self._sweep

    # ---- keep-alive ---------------------------------------------------------------------------------

    async def _feed_watchdog_if_due(self) -> None:
        if not self._running or self.keepalive_interval_s is None:
            return
        if self.clock() - self._last_keepalive_s >= self.keepalive_interval_s:
            await self.keep_alive()

    def _start_keepalive_task(self) -> None:
        if self.keepalive_interval_s is None or self._keepalive_task is not None:
            return
        self._keepalive_task = asyncio.get_running_loop().create_task(
            self._keepalive_loop(self.keepalive_interval_s), name=f"{type(self).__name__} keep-alive"
        )

    async def _keepalive_loop(self, interval_s: float) -> None:
        while True:
            await asyncio.sleep(interval_s)
            try:
                await self._feed_watchdog_if_due()
                self.keepalive_error = None
            except ExciterError as exc:  # keep trying: the operations report their own errors
                if self.keepalive_error is None:
                    log.warning("plate exciter keep-alive failed: %s", exc)
                self.keepalive_error = exc

    def _stop_supervision(self) -> None:
        self._running = False
        task, self._keepalive_task = self._keepalive_task, None
        if task is not None and task is not _current_task():
            task.cancel()

    # ---- wire side, per back end -------------------------------------------------------------------

    @abstractmethod
    async def _write_sweep(self, settings: SweepSettings) -> None:
        """Encode everything first (ExciterEncodingError before any write), then send the sweep."""

    @abstractmethod
    async def _send_command(self, command: CommandCode) -> None: ...

    @abstractmethod
    async def _send_keepalive(self, counter: int) -> None:
        """Feed the drive watchdog; counter is 0..255 and changes on every call."""

    @abstractmethod
    async def _read_status(self) -> ExciterStatus: ...

    @abstractmethod
    async def _close_transport(self) -> None: ...


def _current_task() -> asyncio.Task[object] | None:
    with contextlib.suppress(RuntimeError):
        return asyncio.current_task()
    return None
