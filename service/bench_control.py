"""The one bench a service owns: its devices, one sweep at a time, the emergency stop.

`BenchController` is what the API (and the inspection-line scheduler) talks to. It never blocks the caller's
event loop: a sweep runs in a thread of its own with its own asyncio loop (daq.sweep.run.run_sweep), and
the state the API reads (busy, the running sweep's latest progress, the last outcome) is kept under a lock
and copied out, so the status endpoint costs microseconds.

With `simulated=True` and no configuration, the controller starts a SimulatedBench (simulated lasers and a
Modbus plate drive on loopback, the preset vehicle of the bench model) on a manual clock that each sweep
moves (SimulatedPacing): sweeps are deterministic and run as fast as the machine allows. With a bench
configuration the devices run on their own and sweeps follow the wall clock.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from daq.bench_config import BenchConfig
from daq.live_view import LiveView
from daq.sources.laser_source import SourceStatistics
from daq.sweep.model import SweepOutcome, SweepProgress, SweepRequest
from daq.sweep.pacing import Pacing, RealtimePacing, SimulatedPacing
from daq.sweep.plan import SweepPlan, plan_sweep
from daq.sweep.run import SweepError, check_output, run_sweep
from estimator.errors import ConflictError, one_line
from service.simulated_bench import SimulatedBench, vehicle_preset

log = logging.getLogger("shockbench.bench")

SERVICE_STOPPED = "service stopped"
"""The reason a sweep cut short by the service's own stop (Ctrl-C, SIGTERM) is recorded with; such a sweep
is failed, not aborted (nobody asked for it to end)."""
STARTUP_STOP_TIMEOUT_S = 5.0
STARTUP_STOP_ATTEMPTS = 3

SweepDone = Callable[[str, SweepOutcome | None, str], None]
"""Called in the sweep's thread when it ends: (sweep id, outcome or None, error message if it never began)."""


class BenchBusyError(ConflictError, RuntimeError):
    """A sweep is already running on this bench."""


@dataclass(frozen=True)
class BenchState:
    """A snapshot of the BenchController for the status endpoint (GET /bench; BenchOut is its API schema)."""

    name: str
    model: str
    simulated: bool
    busy: bool
    """A sweep runs, or the end of the one that ran is being stored (its `done`)."""
    sweep_id: str | None
    progress: SweepProgress | None
    devices: list[dict[str, str]] = field(default_factory=list)


class BenchController:
    """The bench the service owns: one sweep at a time on it, its status, and the stop on shutdown. Exists
    so that the API routes and the scheduler share one owner of the devices."""

    def __init__(
        self, config: BenchConfig | None = None, *, simulated: bool = False, model: str = "quarter-car"
    ):
        if config is None and not simulated:
            raise ValueError("a bench needs a configuration, or simulated=True")
        self.simulated = simulated and config is None
        self._bench: SimulatedBench | None = None
        if self.simulated:
            self._bench = SimulatedBench(vehicle_preset(model), name="simulated bench")
            config = self._bench.start()
        assert config is not None
        self.config = config
        self._devices = self._configured_devices(config)  # fixed with the configuration: built once
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._sweep_id: str | None = None
        self._ending: str | None = None
        """A sweep whose thread has ended and whose end its `done` is storing: reported busy until then."""
        self._progress: SweepProgress | None = None
        self._last_progress: SweepProgress | None = None  # kept after the sweep: what the devices delivered
        self._abort = threading.Event()
        self._emergency = threading.Event()
        self._service_stopping = False
        self.live = LiveView()
        """The running (or last) sweep's rows, decimated, for screens (GET /bench/live)."""

    def stop_drive(self, timeout_s: float = STARTUP_STOP_TIMEOUT_S) -> str:
        """Command the drive to stop (controlled stop), whatever it is doing: at start-up, before anything
        else, because a service that crashed (SIGKILL, power cut on the host) may have left the plate
        running, and only the drive's watchdog would otherwise stop it. Returns what happened, in words;
        never raises (an unreachable drive is logged, and the bench's endpoints then say so themselves)."""
        error = ""
        for attempt in range(1, STARTUP_STOP_ATTEMPTS + 1):  # a second STOP does no harm; a lost one does
            try:
                asyncio.run(asyncio.wait_for(self._direct_command(emergency=False), timeout_s))
            except Exception as exc:
                error = one_line(exc)
                log.warning("stop command at start-up, attempt %d: %s", attempt, error)
                continue
            message = f"drive {self.config.exciter.name!r} commanded to stop at start-up"
            log.info("%s", message)
            return message
        message = f"could not command the drive {self.config.exciter.name!r} to stop at start-up: {error}"
        log.error("%s", message)
        return message

    async def _direct_command(self, emergency: bool) -> None:
        """Open the drive, send one stop (controlled, or emergency), close it: with no sweep running there
        is no open driver to send it through."""
        exciter = await self.config.exciter.open(envelope=self.config.safety_envelope())
        try:
            await (exciter.emergency_stop() if emergency else exciter.stop())
        finally:
            await exciter.close()

    def service_stopping(self) -> None:
        """The service begins to stop (a signal; any thread): a running sweep ends now with a controlled
        stop, recorded as failed, "service stopped" (not after open connections have drained), and no new
        sweep starts."""
        with self._lock:
            self._service_stopping = True
            self._abort.set()

    def close(self) -> None:
        """The service stops: abort a running sweep (controlled stop, recording kept, the sweep recorded as
        failed, "service stopped"), wait for it, stop simulated devices."""
        self.service_stopping()
        thread = self._thread
        if thread is not None:
            thread.join(timeout=30)
        if self._bench is not None:
            self._bench.close()
            self._bench = None

    # ---- state ----------------------------------------------------------------------------------------

    def state(self) -> BenchState:
        with self._lock:
            return BenchState(
                name=self.config.name,
                model=str(self.config.model),
                simulated=self.simulated,
                busy=self._thread is not None or self._ending is not None,
                sweep_id=self._sweep_id or self._ending,
                progress=self._progress,
                devices=list(self._devices),
            )

    def devices(self) -> list[dict[str, str]]:
        """What the configuration names, each with its `state` in words: the exciter's phase and frequency,
        each laser's samples, rate and last error, while a sweep runs; after one, what the last sweep got
        from each (a live check of an idle device is `shockbench probe`'s job)."""
        with self._lock:
            busy, progress = self._thread is not None, self._last_progress
        sources = {s.name: s for s in progress.sources} if progress is not None else {}
        found = []
        for device in self._devices:
            state = dict(device)
            if device["kind"] == "exciter":
                state["state"] = (
                    f"{progress.phase.value} at {progress.frequency_Hz:.2f} Hz"
                    if busy and progress is not None
                    else "stopped"
                )
            else:
                state["state"] = _laser_state(sources.get(device["name"]), busy)
            found.append(state)
        return found

    @staticmethod
    def _configured_devices(config: BenchConfig) -> list[dict[str, str]]:
        found = [{"name": config.exciter.name, "kind": "exciter", "url": config.exciter.url}]
        for laser in config.lasers:
            found.append(
                {
                    "name": laser.name,
                    "kind": "laser",
                    "url": laser.url,
                    "channel": laser.channel,
                    "head": laser.head,
                }
            )
        return found

    @property
    def stopping(self) -> bool:
        """The service is stopping: no sweep starts any more."""
        return self._service_stopping

    @property
    def busy(self) -> bool:
        with self._lock:
            return self._thread is not None

    # ---- sweeps ---------------------------------------------------------------------------------------

    def plan(self, request: SweepRequest, *, vehicle_field: str = "vehicle") -> SweepPlan:
        """The request checked against this bench, once (daq.sweep.plan; SweepError naming the field)."""
        return plan_sweep(self.config, request, vehicle_field=vehicle_field)

    def start_sweep(self, sweep_id: str, plan: SweepPlan, out_path: Path, done: SweepDone) -> None:
        """Start a planned sweep in its own thread; BenchBusyError if one runs, SweepError if it cannot
        begin (the service stopping, the recording's place taken)."""
        with self._lock:
            if self._thread is not None:
                raise BenchBusyError(f"bench {self.config.name!r} is running sweep {self._sweep_id}")
            if self._service_stopping:
                raise SweepError("the service is stopping")
            check_output(out_path)
            self._abort.clear()
            self._emergency.clear()
            self._sweep_id, self._progress = sweep_id, None
            self.live.start(self.config.channels, label=sweep_id)
            self._thread = threading.Thread(
                target=self._run,
                args=(sweep_id, plan, out_path, done),
                name=f"sweep {sweep_id}",
                daemon=True,
            )
            self._thread.start()

    def _pacing(self) -> Pacing:
        return SimulatedPacing(self._bench) if self._bench is not None else RealtimePacing()

    def _on_progress(self, progress: SweepProgress) -> None:
        with self._lock:
            self._progress = progress
            self._last_progress = progress

    def _run(self, sweep_id: str, plan: SweepPlan, out_path: Path, done: SweepDone) -> None:
        outcome: SweepOutcome | None = None
        error = ""
        try:
            outcome = asyncio.run(
                run_sweep(
                    self.config,
                    plan,
                    out_path,
                    pacing=self._pacing(),
                    progress=self._on_progress,
                    abort=self._abort,
                    emergency=self._emergency,
                    abort_reason=self._abort_reason,
                    live=self.live,
                )
            )
        except SweepError as exc:
            error = str(exc)
        except Exception as exc:  # the thread must report, whatever happened
            error = f"{type(exc).__name__}: {exc}"
        finally:
            # The bench is free for the next sweep now (the scheduler, woken by `done`, may start it), but
            # the state reads busy with this sweep until `done` has stored its end: a screen that saw the
            # bench free opened the sweep and found it still "running" in the database, with no result.
            with self._lock:
                self._thread = None
                self._sweep_id = None
                self._ending = sweep_id
            try:
                done(sweep_id, outcome, error)
            finally:
                with self._lock:
                    if self._ending == sweep_id:
                        self._ending = None

    def _abort_reason(self) -> str:
        return SERVICE_STOPPED if self._service_stopping else "aborted by the operator"

    def abort(self, sweep_id: str) -> bool:
        """Controlled stop of the running sweep if it is `sweep_id`; False if that sweep is not running."""
        with self._lock:
            if self._sweep_id != sweep_id:
                return False
            self._abort.set()
            return True

    def emergency_stop(self) -> str:
        """Emergency stop: the running sweep ends with one (recording kept); with no sweep running, the
        command goes straight to the drive. Returns what was done, in words."""
        with self._lock:
            running = self._thread is not None
            if running:
                self._emergency.set()
        if running:
            return "emergency stop requested from the running sweep"
        asyncio.run(self._direct_command(emergency=True))
        return "emergency stop sent to the drive"


def _laser_state(stats: SourceStatistics | None, busy: bool) -> str:
    """A laser's state in words, from what it delivered in the running (or last) sweep."""
    if stats is None:
        return "waiting for the sweep's connection" if busy else "idle (not read since the service started)"
    delivered = f"{stats.samples} samples at {stats.achieved_rate_Hz:.0f} Hz"
    trouble = f", {stats.failed_reads} failed reads" if stats.failed_reads else ""
    error = f", last error: {stats.last_error}" if stats.last_error else ""
    return f"{'reading' if busy else 'idle; last sweep'}: {delivered}{trouble}{error}"
