"""One asyncio interface for every plate exciter back end (Modbus TCP/RTU, CAN).

`PlateExciter` holds what every back end shares, so it exists once:

* the safety envelope: a sweep is checked before anything is sent, and while it runs every status the
  drive reports is checked too (frequency, plate position, running past the sweep's end): a breach gets an
  emergency stop from the driver itself, then `EnvelopeBreachError`;
* supervision and the host keep-alive. There is no background keep-alive: the keep-alive that feeds the
  drive's watchdog goes out only from a supervision step, `supervise()` (and `status()`, which is one):
  read the status, check it (drive fault, envelope, the caller's own checks), and only then feed the
  watchdog, at most every `keepalive_interval_s` on the injectable `clock`. A host that stops supervising,
  cannot read the status, or finds something wrong sends no more keep-alives, and the drive's watchdog
  stops the plate. The watchdog therefore proves that the host reads and checks the drive, not merely
  that its event loop runs;
* the start/stop bookkeeping (a start needs a configured sweep and a drive not in fault), and `close()`
  stopping a plate this driver started and did not stop (controlled stop, else emergency stop).

A back end implements the wire side only: `open`, `_write_sweep`, `_send_command`, `_send_keepalive`,
`_read_status`, `_close_transport`.
"""

from __future__ import annotations

import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable

from drivers.exciter.codes import CommandCode, ExciterState, ExciterStatus
from drivers.exciter.envelope import SafetyEnvelope
from drivers.exciter.errors import EnvelopeBreachError, ExciterDeviceExceptionError, ExciterError
from estimator.sweep import SweepSettings

__all__ = ["ExciterState", "ExciterStatus", "PlateExciter"]

log = logging.getLogger(__name__)

DEFAULT_KEEPALIVE_INTERVAL_S = 0.1
"""Shortest time between two keep-alives sent by supervision steps; drives trip their watchdog after
several missed periods (the simulated drive after 0.5 s, a typical real one after 1 s)."""

StatusCheck = Callable[["ExciterStatus"], None]
"""A caller's own check of a status during a supervision step; it raises to withhold the keep-alive."""


class PlateExciter(ABC):
    """A plate drive controller: configure a sweep, start, stop (controlled), emergency stop, status.

    Use as `async with exciter:` (open/close) or call `open()` / `close()`. While a sweep runs, call
    `supervise()` (or `status()`) every cycle: it is what feeds the drive's watchdog (see the module).
    Closing stops a plate this driver started and has not stopped, best effort, then closes the link.

    envelope: the sweeps allowed (default: SafetyEnvelope(), 4 mm / 25 Hz / 300 s).
    keepalive_interval_s: shortest time between keep-alives sent by supervision steps; None sends one
        with every supervision step.
    clock: seconds, for keep-alive spacing and the sweep's running time (and, on CAN, the heartbeat
        supervision).
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
        self.keepalives_sent = 0
        """Keep-alives sent by this driver (each one after a supervision step that passed its checks)."""
        self._sweep: SweepSettings | None = None
        self._running = False
        """Supervised: from start() until stop(), emergency_stop() or close(); keep-alives only then."""
        self._moving = False
        """Started, and no stop command acknowledged since: close() must stop the plate."""
        self._started_s = 0.0
        self._keepalive_counter = 0
        self._last_keepalive_s = -float("inf")

    # ---- public interface -------------------------------------------------------------------------

    @abstractmethod
    async def open(self) -> None:
        """Connect to the drive (the transport only: nothing is written)."""

    async def configure_sweep(self, settings: SweepSettings) -> None:
        """Check the sweep against the envelope, then write it to the drive (it does not start)."""
        self.envelope.check(settings)
        await self._write_sweep(settings)
        self._sweep = settings

    async def start(self) -> None:
        """Start the configured sweep. Refused (ExciterDeviceFaultError) if the drive is in fault, also when
        it trips between the status check and START and refuses START itself: a Modbus drive answers that
        with an exception code, so its status is read again and a fault is raised as the fault it is (as
        CAN's REJECTED_FAULT and CiA 402's own state check say it)."""
        if self._sweep is None:
            raise ExciterError("no sweep configured: call configure_sweep first")
        self.envelope.check(self._sweep)  # the envelope object may have been replaced since configure
        (await self.status()).raise_for_fault()
        self._moving = True  # from here on a lost answer may still mean a moving plate
        try:
            await self._send_command(CommandCode.START)
        except ExciterDeviceExceptionError as refusal:
            try:
                (await self.status()).raise_for_fault()
            except ExciterError as fault:
                raise fault from refusal
            raise
        self._running = True
        self._started_s = self.clock()
        self._last_keepalive_s = self._started_s  # START arms the drive's watchdog: a full period to go

    async def stop(self) -> None:
        """Controlled stop: the drive ramps the amplitude down, then the plate rests.

        Supervision (hence the keep-alive) ends first, whatever the outcome: should the stop command be
        lost, the drive's watchdog stops the plate anyway."""
        self._running = False
        await self._send_command(CommandCode.STOP)
        self._moving = False

    async def emergency_stop(self) -> None:
        """Immediate stop: sent at once, without any preliminary traffic (supervision ends as for stop)."""
        self._running = False
        await self._send_command(CommandCode.EMERGENCY_STOP)
        self._moving = False

    async def reset_fault(self) -> None:
        """Acknowledge a latched drive fault (watchdog, drive trip) so the drive accepts START again."""
        await self._send_command(CommandCode.RESET_FAULT)

    async def status(self) -> ExciterStatus:
        """Read the drive status. While a sweep runs this is a supervision step (`supervise()` without a
        check of the caller's). A drive in fault is reported here, not raised (see raise_for_fault)."""
        return await self.supervise()

    async def supervise(self, check: StatusCheck | None = None) -> ExciterStatus:
        """One supervision step: read the status; if the plate moves, check it against the envelope
        (breach: emergency stop, then EnvelopeBreachError); run `check` (the caller's own checks, which
        raise to refuse); then, while a sweep runs and the drive is not in fault, feed its watchdog.

        Any error (status read, breach, `check`) propagates before the keep-alive: the watchdog is fed
        only by a host that has just read and approved the drive's state."""
        status = await self._read_status()
        if status.state in (ExciterState.RUNNING, ExciterState.STOPPING):
            await self._check_envelope(status)
        if check is not None:
            check(status)
        if self._running and not status.is_fault:
            await self._feed_watchdog_if_due()
        return status

    async def close(self) -> None:
        """Stop a plate this driver started and did not stop (controlled stop, emergency stop if that
        fails; best effort, errors logged), then release the transport. Idempotent."""
        self._running = False
        if self._moving:
            await self._stop_best_effort()
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

    @property
    def supervising(self) -> bool:
        """A sweep was started and not stopped: supervision steps feed the drive's watchdog."""
        return self._running

    # ---- supervision --------------------------------------------------------------------------------

    async def _check_envelope(self, status: ExciterStatus) -> None:
        sweep = self._sweep
        running_for_s = None
        if self._running and status.state is ExciterState.RUNNING:
            running_for_s = self.clock() - self._started_s
        breach = self.envelope.breach(
            status.frequency_Hz,
            status.position_m,
            running_for_s,
            sweep.duration_s if sweep is not None else None,
        )
        if breach is None:
            return
        self._running = False  # no keep-alive from here on, whatever the emergency stop does
        log.error("plate exciter: %s=%r outside the envelope (%s=%r): emergency stop", *breach)
        try:
            await self.emergency_stop()
            stopped = True
        except ExciterError as exc:
            log.error("emergency stop after an envelope breach failed: %s", exc)
            stopped = False
        raise EnvelopeBreachError(*breach, stopped=stopped)

    async def _feed_watchdog_if_due(self) -> None:
        interval_s = self.keepalive_interval_s
        if interval_s is not None and self.clock() - self._last_keepalive_s < interval_s:
            return
        self._keepalive_counter = (self._keepalive_counter + 1) & 0xFF
        await self._send_keepalive(self._keepalive_counter)
        self._last_keepalive_s = self.clock()
        self.keepalives_sent += 1

    async def _stop_best_effort(self) -> None:
        try:
            await self.stop()
            return
        except Exception as exc:  # best effort on the way out: every failure leads to the next attempt
            log.warning("closing with the plate moving: stop failed (%s); trying an emergency stop", exc)
        try:
            await self.emergency_stop()
        except Exception as exc:
            log.error(
                "closing with the plate moving: emergency stop failed too (%s); the drive's "
                "watchdog stops the plate",
                exc,
            )

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
