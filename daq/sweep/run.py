"""One sweep, end to end: connect, zero the sensors at rest, start the plate's sweep, record the sweep and
the settling, stop the plate, close the recording.

    plan = plan_sweep(config, SweepRequest(sweep, vehicle=load_vehicle_file("car.toml")))
    outcome = await run_sweep(config, plan, Path("run.h5"), pacing=...)

The request was judged once, at the edge, by daq.sweep.plan (lasers, the vehicle's model, the envelope, the
bandwidth); the driver checks the envelope again as the safety net. Before the plate moves, any problem
found here (an existing output file, a laser that does not answer or reads out of range at rest, an exciter
in fault) raises `SweepError` with one line naming it, and nothing is written.

Once the plate has been told to start, nothing raises: every ending comes back as a `SweepOutcome`, and the
recording is kept, closed as complete or as incomplete with the reason:

* the sweep and settling ran out: a stop command as a matter of course, complete;
* `abort` set (operator, service) or the task cancelled (Ctrl-C): controlled stop, "aborted ...";
* `emergency` set (the service's emergency stop): emergency stop, "emergency stop by the operator";
* a source silent for `silence_timeout_s` (no new samples: the line is down, the amplifier stopped
  answering or sampling), longer when its line has lost a reply and is in OMRON's wait for a late one
  (daq/sweep/silence.py): controlled stop, "sensor silence: ..." with the source's last error. One lost
  reply is a gap in that line's channels, not a stop;
* the exciter's link lost (status cannot be read): controlled stop attempted, "lost link to exciter ...";
  the drive refuses the status read (an exception code): controlled stop, "exciter refused ...";
* the exciter reports a fault: emergency stop, "exciter fault 0x....";
* the drive reports a frequency or plate position outside the safety envelope, or runs past the sweep's
  end: the driver's own emergency stop, "envelope breach: ...";
* any other error on the host: controlled stop, "host error: ...".

Supervision: every cycle reads the drive's status, checks it (fault, envelope, then the sources' silence)
and only then feeds the drive's watchdog (PlateExciter.supervise). There is no other keep-alive: when a
status read fails or a check finds something wrong, the keep-alive ends with that cycle.

A controlled stop that cannot be sent is followed by an emergency stop; if neither reaches the drive, its
watchdog stops the plate once the keep-alive has ended (both stops end it first), and the outcome says so.
After a stop the recording continues until the drive reports the plate at rest (at most
`STOP_RECORD_LIMIT_S`), so the ramp-down is in the data.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np

from daq.bench_config import BenchConfig
from daq.live_view import LiveView
from daq.recorder import Recorder, max_interval_s
from daq.sources.laser_source import LaserSource
from daq.storage.hdf5_recording import MetadataValue, RecordingWriter
from daq.sweep.devices import Devices, DriverDevices
from daq.sweep.model import (
    SAMPLE_TIME_S,
    StopKind,
    SweepError,
    SweepOutcome,
    SweepPhase,
    SweepProgress,
    SweepRequest,
)
from daq.sweep.pacing import Pacing, RealtimePacing
from daq.sweep.plan import SweepPlan
from daq.sweep.silence import NO_ERROR, silence_reason
from drivers.exciter.codes import ExciterState, ExciterStatus
from drivers.exciter.errors import EnvelopeBreachError, ExciterDeviceExceptionError
from drivers.interfaces import Exciter, LaserLine

log = logging.getLogger(__name__)

STEP_S = 0.05
"""The orchestration's cycle: recorder step, exciter status, silence check, progress (s)."""
DEFAULT_SILENCE_TIMEOUT_S = 0.5
TIME_TOLERANCE_S = 1e-6
"""Sums of float steps land a hair short of a target time; closer than this counts as there."""
STOP_RECORD_LIMIT_S = 3.0
"""After a stop command, recording goes on until the plate rests, at most this long (s)."""
REST_MIN_SAMPLES = 5
REST_MAX_STD_M = 0.5e-3
"""A channel moving more than this (standard deviation at rest) means the vehicle is not at rest."""


class SweepFaultError(Exception):
    """Ends a running sweep early: `reason` goes into the recording; `emergency` asks for an emergency
    stop (an exciter fault) instead of a controlled one."""

    def __init__(self, reason: str, emergency: bool = False) -> None:
        super().__init__(reason)
        self.reason = reason
        self.emergency = emergency


class SweepAbortedError(Exception):
    """The operator (or the service) aborted the sweep."""


async def run_sweep(
    config: BenchConfig,
    plan: SweepPlan,
    out_path: Path | str,
    *,
    pacing: Pacing | None = None,
    progress: Callable[[SweepProgress], None] | None = None,
    abort: threading.Event | None = None,
    emergency: threading.Event | None = None,
    silence_timeout_s: float = DEFAULT_SILENCE_TIMEOUT_S,
    abort_reason: Callable[[], str] | None = None,
    live: LiveView | None = None,
    devices: Devices | None = None,
) -> SweepOutcome:
    """Run one planned sweep (daq.sweep.plan.plan_sweep on this `config`) on the bench `config` describes
    and record it at out_path (HDF5). See the module.

    abort: set it to end the sweep with a controlled stop; emergency: set it for an emergency stop (both
    are looked at every orchestration cycle, STEP_S). abort_reason: what an abort is recorded as (default
    "aborted by the operator"; the service says "service stopped" when its own stop aborts the sweep).
    live: a daq.live_view.LiveView the recorder copies its rows to, decimated, for screens (its owner
    starts it with the bench's channels). devices: how the lasers and the exciter are reached (default: the
    drivers, daq.sweep.devices.DriverDevices; a simulated bench on a manual clock passes one whose lines
    reach its amplifiers in process on that clock; unit tests pass MockDevices)."""
    if plan.bench != config.name:  # a programming error, not an input: plans are made for one bench
        raise ValueError(f"a sweep planned for bench {plan.bench!r} cannot run on bench {config.name!r}")
    run = _SweepRun(config, plan.request, Path(out_path), pacing or RealtimePacing(), progress, abort)
    if abort_reason is not None:
        run.abort_reason = abort_reason
    run.emergency = emergency or threading.Event()
    run.silence_timeout_s = silence_timeout_s
    run.live = live
    run.devices = devices or DriverDevices()
    return await run.run()


def check_output(out_path: Path) -> None:
    """The recording's place (SweepError, one line): never over an existing file, in an existing folder."""
    if out_path.exists():
        raise SweepError(f"{out_path}: already exists; a recording is never overwritten")
    if not out_path.parent.is_dir():
        raise SweepError(f"{out_path.parent}: no such folder")


class _SweepRun:
    def __init__(
        self,
        config: BenchConfig,
        request: SweepRequest,
        out_path: Path,
        pacing: Pacing,
        progress: Callable[[SweepProgress], None] | None,
        abort: threading.Event | None,
    ) -> None:
        self.config = config
        self.request = request
        self.out_path = out_path
        self.pacing = pacing
        self.clock = pacing.host_clock
        self.on_progress = progress
        self.abort = abort or threading.Event()
        self.abort_reason: Callable[[], str] = lambda: "aborted by the operator"
        self.emergency = threading.Event()
        self.silence_timeout_s = DEFAULT_SILENCE_TIMEOUT_S
        self.ports: list[LaserLine] = []
        self.devices: Devices = DriverDevices()
        self.sources: list[LaserSource] = []
        self.models: dict[str, str] = {}
        self.exciter: Exciter | None = None
        self.writer: RecordingWriter | None = None
        self.recorder: Recorder | None = None
        self.live: LiveView | None = None
        self.phase = SweepPhase.CONNECTING
        self.frequency_Hz = 0.0
        self.started_s = math.nan

    # ---- the run ----------------------------------------------------------------------------------------

    async def run(self) -> SweepOutcome:
        check_output(self.out_path)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        complete, reason, stop = False, "", StopKind.NOT_STARTED
        cancelled: BaseException | None = None
        try:
            await self._connect()
            rest = await self._zero()
            self._open_recording(rest)
            assert self.exciter is not None
            await self.exciter.configure_sweep(self.request.sweep)
            stop = StopKind.CONTROLLED  # from here on the plate may move
            await self.exciter.start()
            self.started_s = self.clock()
            self._start_recorder(rest)
            await self._record_sweep()
            stop = await self._stop(emergency=False, at_end=True)
            complete = True
        except SweepError:
            if stop is not StopKind.NOT_STARTED:
                raise AssertionError("SweepError after the start") from None
            await self._close_devices()
            raise
        except (SweepAbortedError, asyncio.CancelledError, KeyboardInterrupt) as exc:
            if not isinstance(exc, SweepAbortedError):
                cancelled = exc
            reason = self.abort_reason() if isinstance(exc, SweepAbortedError) else "aborted by the operator"
            stop = await self._stop_if_moving(stop, emergency=False)
        except SweepFaultError as fault:
            reason = fault.reason
            stop = await self._stop_if_moving(stop, emergency=fault.emergency)
        except Exception as exc:  # the host's own failure: still stop the plate and keep the data
            log.exception("sweep failed on the host")
            reason = f"host error: {type(exc).__name__}: {exc}"
            stop = await self._stop_if_moving(stop, emergency=False)
        if self.writer is None and not complete:
            await self._close_devices()
            if cancelled is not None:
                raise cancelled
            raise SweepError(reason or "the sweep did not begin")
        outcome = await self._finish(complete, reason, stop, cpu0, wall0)
        if cancelled is not None:
            raise cancelled
        return outcome

    async def _stop_if_moving(self, stop: StopKind, *, emergency: bool) -> StopKind:
        if stop is StopKind.NOT_STARTED:
            return stop
        return await self._stop(emergency=emergency, at_end=False)

    # ---- connecting and zeroing ---------------------------------------------------------------------

    async def _connect(self) -> None:
        self._report()
        lines: dict[str, list[LaserSource]] = defaultdict(list)
        for laser in self.config.lasers:
            url, node = laser.device()
            port = next((p for p in self.ports if p.pyserial_url == url), None)
            try:
                if port is None:
                    port = await asyncio.to_thread(self.devices.open_line, laser.url)
                    self.ports.append(port)
                amplifier = self.devices.amplifier(port, node, laser.amplifier_config())
                self.models[laser.name] = await asyncio.to_thread(amplifier.read_model)
            except Exception as exc:
                raise SweepError(f"laser {laser.name!r} ({laser.url}): {exc}") from None
            source = LaserSource(laser, amplifier, host_clock=self.clock)
            self.sources.append(source)
            lines[url].append(source)
        try:
            self.exciter = await self.devices.open_exciter(
                self.config.exciter, self.config.safety_envelope(), self.clock
            )
            status = await self.exciter.status()
        except Exception as exc:
            exciter = self.config.exciter
            raise SweepError(f"exciter {exciter.name!r} ({exciter.url}): {exc}") from None
        if status.is_fault:
            raise SweepError(f"exciter in fault 0x{status.fault_code:04X}: reset the drive first")
        if status.state is not ExciterState.IDLE:
            raise SweepError(f"the plate is not at rest (drive state {status.state}); stop it first")
        for port in self.ports:  # the sources wait out a late reply by skipping polls, not in the port
            port.waits_for_late_replies = False
        self.pacing.start(list(lines.values()))

    async def _zero(self) -> dict[str, tuple[float, float]]:
        """Read at rest: per channel (mean m, typical interval s). Freezes the device clock mappings."""
        self.phase = SweepPhase.ZEROING
        self._report()
        readers = [source.buffer.reader("zeroing", from_oldest=True) for source in self.sources]
        await self.pacing.wait(self.request.rest_s)
        rest: dict[str, tuple[float, float]] = {}
        for source, reader in zip(self.sources, readers, strict=True):
            result = reader.read()
            reader.close()
            values = result.values[:, 0]
            where = f"laser {source.name!r} ({source.channel})"
            if result.count < REST_MIN_SAMPLES:
                error = source.statistics().last_error or NO_ERROR
                raise SweepError(
                    f"{where}: {result.count} samples in {self.request.rest_s:g} s at rest ({error})"
                )
            if np.isnan(values).any():
                raise SweepError(f"{where}: out of measuring range at rest; check the head's position")
            spread = float(np.std(values))
            if spread > REST_MAX_STD_M:
                raise SweepError(f"{where}: moves by {spread * 1e3:.2f} mm (std) at rest; is all still?")
            typical = float(np.median(np.diff(result.timestamps_s)))
            if source.streaming:
                source.mapping.freeze()
            rest[source.channel] = (float(np.mean(values)), typical)
        return rest

    def _start_recorder(self, rest: dict[str, tuple[float, float]]) -> None:
        """Rows from the start command on (t = 0 there); the samples at rest lead into row 0."""
        assert self.writer is not None
        self.recorder = Recorder(
            self.sources,
            self.writer,
            origin_s=self.started_s,
            max_intervals_s={s.channel: max_interval_s(s, rest[s.channel][1]) for s in self.sources},
            rest_offsets_m={channel: mean for channel, (mean, _) in rest.items()},
            live=self.live,
        )

    def _open_recording(self, rest: dict[str, tuple[float, float]]) -> None:
        metadata = self._metadata(rest)
        nominal = {s.channel: (1.0 / s.period_s if s.period_s else 0.0) for s in self.sources}
        self.writer = RecordingWriter(
            self.out_path,
            self.config.channels,
            SAMPLE_TIME_S,
            metadata,
            vehicle=self.request.vehicle,
            rates_Hz=nominal,
        )

    def _metadata(self, rest: dict[str, tuple[float, float]]) -> dict[str, MetadataValue]:
        sweep = self.request.sweep
        meta: dict[str, MetadataValue] = {
            "bench": self.config.name,
            "bench_model": str(self.config.model),
            "operator": self.request.operator,
            "sweep_start_Hz": sweep.start_Hz,
            "sweep_stop_Hz": sweep.stop_Hz,
            "sweep_amplitude_m": sweep.amplitude_m,
            "sweep_duration_s": sweep.duration_s,
            "sweep_law": str(sweep.law),
            "settle_s": self.request.settle_s,
            "exciter": f"{self.config.exciter.name} {self.config.exciter.url}",
            "interpolation": "cubic (4-point Lagrange) onto the 1 ms grid; linear at edges; gaps NaN",
            "time_origin": "t = 0 s when the drive acknowledged the start command",
        }
        for source in self.sources:
            laser = source.laser
            channel = laser.channel
            meta[f"laser.{channel}"] = f"{laser.name} {laser.url} head {laser.head} sign {laser.sign:+d}"
            meta[f"device_model.{laser.name}"] = self.models.get(laser.name, "")
            meta[f"clock.{channel}"] = str(source.buffer.clock)
            meta[f"rest_offset_m.{channel}"] = rest[channel][0]
        return meta

    # ---- recording --------------------------------------------------------------------------------------

    async def _record_sweep(self) -> None:
        total_s = self.request.recorded_s
        self.phase = SweepPhase.SWEEPING
        while (elapsed := self.clock() - self.started_s) < total_s - TIME_TOLERANCE_S:
            if self.emergency.is_set():
                raise SweepFaultError("emergency stop by the operator", emergency=True)
            if self.abort.is_set():
                raise SweepAbortedError()
            if elapsed >= self.request.sweep.duration_s:
                self.phase = SweepPhase.SETTLING
            await self.pacing.wait(min(STEP_S, max(total_s - elapsed, 1e-3)))
            await self._cycle()

    async def _cycle(self) -> ExciterStatus:
        """One orchestration cycle: write the final rows, supervise the drive (status read and checked, the
        sources checked, then the keep-alive), report."""
        assert self.recorder is not None and self.exciter is not None
        await asyncio.to_thread(self.recorder.step)
        try:
            status = await self.exciter.supervise(self._check_cycle)
        except SweepFaultError:
            raise
        except EnvelopeBreachError as breach:
            raise SweepFaultError(f"envelope breach: {breach}", emergency=True) from None
        except ExciterDeviceExceptionError as exc:
            raise SweepFaultError(f"exciter refused the status read: {exc}") from None
        except Exception as exc:
            raise SweepFaultError(f"lost link to exciter: {type(exc).__name__}: {exc}") from None
        self.frequency_Hz = status.frequency_Hz
        self._report()
        return status

    def _check_cycle(self, status: ExciterStatus) -> None:
        """The cycle's checks, run after the status read and before the keep-alive (SweepFaultError)."""
        if status.is_fault:
            raise SweepFaultError(f"exciter fault 0x{status.fault_code:04X}", emergency=True)
        silence = silence_reason(self.sources, self.silence_timeout_s)
        if silence is not None:
            raise SweepFaultError(silence)

    # ---- stopping and finishing -------------------------------------------------------------------------

    async def _stop(self, *, emergency: bool, at_end: bool) -> StopKind:
        """Stop the plate; on anything but the regular end, keep recording until it rests."""
        self.phase = SweepPhase.STOPPING
        exciter = self.exciter
        if exciter is None:
            return StopKind.NOT_STARTED
        kind = StopKind.END_OF_SWEEP if at_end else StopKind.CONTROLLED
        try:
            if emergency:
                kind = StopKind.EMERGENCY
                await exciter.emergency_stop()
            else:
                await exciter.stop()
        except Exception as exc:
            log.warning("stop command failed (%s); trying an emergency stop", exc)
            try:
                await exciter.emergency_stop()
                kind = StopKind.EMERGENCY
            except Exception as again:
                log.error("emergency stop failed too (%s); the drive's watchdog must stop the plate", again)
                return StopKind.WATCHDOG
        if not at_end:
            await self._record_until_rest()
        return kind

    async def _record_until_rest(self) -> None:
        deadline = self.clock() + STOP_RECORD_LIMIT_S
        while self.clock() < deadline and self.exciter is not None and self.recorder is not None:
            await self.pacing.wait(STEP_S)
            await asyncio.to_thread(self.recorder.step)
            try:
                status = await self.exciter.status()
            except Exception:
                return
            self.frequency_Hz = status.frequency_Hz
            self._report()
            if status.state in (ExciterState.IDLE, ExciterState.FAULT):
                return

    async def _finish(
        self, complete: bool, reason: str, stop: StopKind, cpu0: float, wall0: float
    ) -> SweepOutcome:
        end_s = self.clock()
        self.pacing.stop()
        rows = gap_rows = overruns = 0
        try:
            if self.recorder is not None:
                self.recorder.finish(end_s)
                stats = self.recorder.statistics()
                rows, gap_rows, overruns = stats.rows, stats.gap_rows, stats.overrun_samples
        except Exception as exc:  # keep what is on disk; say why the rest is missing
            log.exception("recorder failed while finishing")
            complete, reason = False, reason or f"host error while finishing: {exc}"
        if stop is StopKind.WATCHDOG:
            reason = f"{reason}; no stop command reached the drive (its watchdog stops the plate)"
        sources = tuple(source.statistics() for source in self.sources)
        if self.writer is not None:
            rates = {s.channel: s.achieved_rate_Hz for s in sources}
            self.writer.close(complete, reason or None, rates)
        await self._close_devices()
        self.phase = SweepPhase.DONE
        self._report()
        return SweepOutcome(
            path=self.out_path if self.writer is not None else None,
            complete=complete,
            reason=reason,
            stop=stop,
            rows=rows,
            gap_rows=gap_rows,
            overrun_samples=overruns,
            sources=sources,
            cpu_s=time.process_time() - cpu0,
            wall_s=time.perf_counter() - wall0,
        )

    async def _close_devices(self) -> None:
        self.pacing.stop()
        if self.exciter is not None:
            with contextlib.suppress(Exception):
                await self.exciter.close()
        for port in self.ports:
            with contextlib.suppress(Exception):
                port.close()
        self.ports.clear()

    def _report(self) -> None:
        if self.on_progress is None:
            return
        elapsed = 0.0 if math.isnan(self.started_s) else self.clock() - self.started_s
        stats = self.recorder.statistics() if self.recorder is not None else None
        self.on_progress(
            SweepProgress(
                phase=self.phase,
                elapsed_s=elapsed,
                total_s=self.request.recorded_s,
                frequency_Hz=self.frequency_Hz,
                rows=stats.rows if stats else 0,
                gap_rows=stats.gap_rows if stats else 0,
                sources=tuple(source.statistics() for source in self.sources),
            )
        )
