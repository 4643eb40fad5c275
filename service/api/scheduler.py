"""The inspection-line scheduler: runs the scheduled tests of the service's bench, one at a time.

A test is a vehicle file plus sweep settings, due at a given time or, with none, as soon as the lane is
free (ScheduleStore). Each pass (`tick`):

1. The running test, if any: while its sweep runs, nothing to do. When the sweep has ended complete, an
   identification job on its recording is queued and the test is done (it names the sweep and the job);
   when the sweep failed or was aborted, the test failed with the sweep's reason.
2. Then, if the bench is free, the next due test (earliest due first) is claimed and its sweep started,
   exactly as `POST /sweeps` starts one. An operator's sweep that took the bench in between puts the test
   back to waiting; a test the bench refuses (its envelope changed since submit) fails with the reason.

Passes run on a timer and whenever something changes (a test is submitted, a sweep ends), in the event
loop; the blocking parts (database, files, starting the sweep) in a thread. Everything is in the database,
so a restart resumes: waiting tests stay waiting, a test whose sweep a crash cut off fails with the
sweep's reason (the sweep store marks it failed at start-up), and a test whose sweep had completed gets
its job. `clock` is injectable: tests move time by hand instead of waiting.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

from pydantic import ValidationError

from estimator.errors import UserError, one_line
from service.api.settings import ServiceSettings
from service.api.sweep_launch import SweepIn, launch_sweep
from service.api.sweep_recordings import accept_sweep_job
from service.bench_control import BenchBusyError, BenchController
from service.jobs.identify_job import IdentifyJobOptions
from service.jobs.manager import JobManager
from service.store.jobs import JobRecord, JobStore
from service.store.models import ScheduleStatus, SweepStatus, utcnow
from service.store.schedules import ScheduleRecord, ScheduleStore
from service.store.sweeps import SweepStore

log = logging.getLogger("shockbench.scheduler")

DEFAULT_POLL_S = 1.0
"""How often a pass runs without a wake-up: the resolution of `run_at`."""


class InspectionScheduler:
    def __init__(
        self,
        settings: ServiceSettings,
        bench: BenchController,
        tests: ScheduleStore,
        sweeps: SweepStore,
        jobs: JobStore,
        manager: JobManager,
        *,
        poll_s: float | None = DEFAULT_POLL_S,
        clock: Callable[[], datetime] = utcnow,
    ) -> None:
        self.settings = settings
        self.bench = bench
        self.tests = tests
        self.sweeps = sweeps
        self.jobs = jobs
        self.manager = manager
        self.poll_s = poll_s
        """None: no timer (passes run on wake-ups and explicit `tick` calls only)."""
        self.clock = clock
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wakeup = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._lock = asyncio.Lock()
        self.passes = 0
        """Passes completed: lets a caller see that a pass has run since it changed something."""

    # ---- life ---------------------------------------------------------------------------------------------

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._task = asyncio.create_task(self._run(), name="inspection-line scheduler")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    def wake(self) -> None:
        """Run a pass soon. Callable from any thread (a sweep's thread calls it when the sweep ends)."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile: nothing left to wake
                loop.call_soon_threadsafe(self._wakeup.set)

    async def _run(self) -> None:
        while True:
            try:
                await self.tick()
            except Exception:  # a pass that fails must not stop the line; the next pass retries
                log.exception("scheduler pass failed")
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._wakeup.wait(), self.poll_s)
            self._wakeup.clear()

    # ---- one pass -----------------------------------------------------------------------------------------

    async def tick(self) -> None:
        """One pass (see the module docstring)."""
        async with self._lock:
            job = await asyncio.to_thread(self._finish_running)
            if job is not None:
                self.manager.enqueue(job)
            await asyncio.to_thread(self._start_next)
            self.passes += 1

    def _finish_running(self) -> JobRecord | None:
        test = self.tests.running(self.bench.config.name)
        if test is None:
            return None
        if test.sweep_id is None:  # claimed, then the service stopped before the sweep was started
            self.tests.finish(
                test.id, ScheduleStatus.FAILED, reason="the service stopped before its sweep began"
            )
            return None
        sweep = self.sweeps.get(test.sweep_id)
        if sweep is None or not sweep.finished:
            return None
        if sweep.status is not SweepStatus.COMPLETE:
            reason = f"sweep {sweep.id} {sweep.status.value}: {sweep.reason or 'no reason given'}"
            self.tests.finish(test.id, ScheduleStatus.FAILED, reason=reason)
            log.warning("scheduled test %d failed: %s", test.id, reason)
            return None
        try:
            options = IdentifyJobOptions.model_validate(test.job_options)
            job = accept_sweep_job(self.settings, self.jobs, sweep, options, test.created_by)
        except (UserError, ValidationError) as exc:
            reason = f"no identification job on sweep {sweep.id}: {_message(exc)}"
            self.tests.finish(test.id, ScheduleStatus.FAILED, reason=reason)
            log.warning("scheduled test %d failed: %s", test.id, reason)
            return None
        self.tests.finish(test.id, ScheduleStatus.DONE, job_id=job.id)
        log.info("scheduled test %d done: sweep %d, job %d queued", test.id, sweep.id, job.id)
        return job

    def _start_next(self) -> None:
        if self.bench.busy or self.bench.stopping:  # a stopping service starts no test (it stays waiting)
            return
        test = self.tests.claim_next(self.bench.config.name, self.clock())
        if test is None:
            return
        try:
            body = sweep_request_of(test)
            sweep = launch_sweep(
                self.bench, self.sweeps, self.settings.data_dir, body, test.created_by, self.wake
            )
        except BenchBusyError:  # an operator's sweep took the bench first: wait for the next gap
            self.tests.release(test.id)
            return
        except UserError as exc:
            self.tests.finish(test.id, ScheduleStatus.FAILED, reason=_message(exc))
            log.warning("scheduled test %d refused by the bench: %s", test.id, _message(exc))
            return
        except (OSError, ValidationError) as exc:
            self.tests.finish(test.id, ScheduleStatus.FAILED, reason=_message(exc))
            return
        self.tests.attach_sweep(test.id, sweep.id)
        log.info("scheduled test %d: sweep %d started", test.id, sweep.id)


def sweep_request_of(test: ScheduleRecord) -> SweepIn:
    """The sweep request of a test: its stored settings and its saved vehicle file."""
    vehicle_toml = Path(test.vehicle_file).read_text(encoding="utf-8")
    return SweepIn.model_validate({**test.sweep_settings, "vehicle_toml": vehicle_toml})


def _message(exc: Exception) -> str:
    if isinstance(exc, ValidationError):
        first = exc.errors()[0]
        return f"{'.'.join(str(p) for p in first['loc'])}: {first['msg']}"
    return one_line(exc)
