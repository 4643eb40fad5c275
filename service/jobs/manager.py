"""The job manager: a FIFO of jobs, one worker process that runs them one at a time, and what happens
when jobs finish, are cancelled, or their worker dies.

Everything here runs on the service's event loop and only awaits: database calls go to a thread, the
worker's messages arrive through a reader thread (service.jobs.process) into an asyncio queue. Two tasks:

- the dispatcher takes the next queued job, marks it running, sends it to the worker and waits for it
  to end;
- the pump handles the worker's messages: progress (kept in memory for /status and the job's GET,
  published to event listeners, written to the database every few seconds), the outcome (written, then
  published), and the worker's death: the job it ran is marked failed with the reason (or cancelled, if
  that was asked for; or put back in the queue if the worker had not taken it yet) and a new worker is
  started, after a back-off if workers keep dying at once.

Cancelling a queued job removes it; cancelling a running one asks the worker to stop it (DE stops after
its current generation) and kills the worker if the job has not stopped within the grace time.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from service.jobs.broker import EventBroker, JobFinishedEvent, JobProgressEvent, JobStateEvent
from service.jobs.messages import (
    CancelJob,
    FromWorker,
    JobCancelled,
    JobFailed,
    JobProgress,
    JobStarted,
    JobSucceeded,
    JsonObject,
    Progress,
    RunJob,
    WorkerExited,
    WorkerReady,
)
from service.jobs.process import WorkerProcess, describe_exit
from service.service_limits import WorkerLimits
from service.store.job_queue import DEFAULT_LEASE_S, JobQueue
from service.store.jobs import RESTART_REASON, JobRecord, JobStore
from service.store.models import JobStatus

log = logging.getLogger("shockbench.jobs")

QUICK_DEATH_S = 10.0
"""A worker that dies sooner than this after its start counts towards the restart back-off."""
MAX_BACKOFF_S = 30.0


@dataclass(frozen=True)
class WorkerSettings:
    nice: int = WorkerLimits.worker_nice
    """Added to the worker's nice value (service.service_limits): the loop keeps priority over estimation."""
    progress_interval_s: float = 0.2
    """The worker sends DE progress at most this often."""
    persist_interval_s: float = 2.0
    """Progress is written to the database at most this often (it is live in memory anyway)."""
    cancel_grace_s: float = 5.0
    """A running job that has not stopped this long after a cancel is stopped by killing its worker."""
    stop_timeout_s: float = 5.0
    lease_s: float = DEFAULT_LEASE_S
    """A job's claim lasts this long unless renewed (every third of it); an instance that died loses its
    jobs to the others after it (service.store.job_queue)."""
    poll_s: float = 1.0
    """With nothing to run, the queue is looked at this often (a job submitted on another instance)."""


@dataclass
class _Current:
    job_id: int
    kind: str
    incarnation: int
    """The worker it was sent to (0: not sent yet)."""
    done: asyncio.Future[None]
    started: bool = False
    progress: Progress | None = None
    cancel_requested: bool = False
    finishing: bool = False
    """Its end is being written (perhaps already in the database): /status no longer shows it."""
    persisted_at: float = -math.inf
    dispatched_at: float = field(default_factory=time.monotonic)
    """When it left the queue (time.monotonic()): its run time, for the metrics, is counted from here."""


@dataclass(frozen=True)
class ManagerStatus:
    worker_alive: bool
    worker_ready: bool
    worker_pid: int | None
    worker_restarts: int
    queue_length: int
    current_job_id: int | None
    current_kind: str | None
    current_progress: Progress | None


@dataclass
class _Worker:
    process: WorkerProcess
    started_at: float = field(default_factory=time.monotonic)
    ready: bool = False


class JobManager:
    def __init__(
        self,
        store: JobStore,
        settings: WorkerSettings = WorkerSettings(),
        completing: Callable[[str, JsonObject], JsonObject] | None = None,
        on_finished: Callable[[str, str, float], None] | None = None,
    ) -> None:
        """completing(kind, result): what to store as a succeeded job's result (the service adds the
        verdict an identification's figures earn under its configured thresholds). on_finished(kind,
        status, run time in s): told of every job that ran here once it ended (the service's metrics). In
        the shared queue this service is named by its store's lane (one instance per lane)."""
        self.store = store
        self.settings = settings
        self.completing = completing
        self.on_finished = on_finished
        self.queue = JobQueue(store.db, store.lane or "default", settings.lease_s)
        self._queued = 0  # the queue's length as last counted (status answers from memory)
        self.broker = EventBroker()
        self.restarts = 0
        self._wakeup = asyncio.Event()
        self._worker_up = asyncio.Event()
        self._events: asyncio.Queue[tuple[int, FromWorker | WorkerExited]] = asyncio.Queue()
        self._worker: _Worker | None = None
        self._incarnation = 0
        self._quick_deaths = 0
        self._current: _Current | None = None
        self._cancel_requests: set[int] = set()
        self._kill_timer: asyncio.TimerHandle | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._loop: asyncio.AbstractEventLoop | None = None

    # life cycle

    async def start(self) -> list[int]:
        """Take back what this instance's previous run held (run again; failed after too many attempts),
        start the worker and the tasks. Returns the ids of the jobs marked failed."""
        self._loop = asyncio.get_running_loop()
        reclaimed = await asyncio.to_thread(self.queue.reclaim_own)
        for job_id in reclaimed.requeued:
            log.warning("job %d was running when this lane's service stopped; it runs again", job_id)
        for job_id in reclaimed.failed:
            log.warning("job %d: %s; marked failed", job_id, RESTART_REASON)
        self._queued = await asyncio.to_thread(self.queue.queued_count)
        if self._queued:
            log.info("%d queued job(s) waiting", self._queued)
        await self._start_worker()
        self._tasks = [
            asyncio.create_task(self._pump(), name="job-events"),
            asyncio.create_task(self._dispatch(), name="job-dispatcher"),
            asyncio.create_task(self._keep(), name="job-leases"),
        ]
        return reclaimed.failed

    async def stop(self) -> None:
        """Stop the tasks and the worker. A job still running is put back in the queue: the next start
        runs it again."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks = []
        if self._kill_timer is not None:
            self._kill_timer.cancel()
        if self._current is not None:
            await asyncio.to_thread(self.store.requeue, self._current.job_id, self.queue.instance)
            self._current = None
        if self._worker is not None:
            await asyncio.to_thread(self._worker.process.stop, self.settings.stop_timeout_s)

    def close_streams_threadsafe(self) -> None:
        """From any thread (e.g. a signal handler): end the event streams, the service is stopping."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self.broker.close)

    def _post(self, incarnation: int, message: FromWorker | WorkerExited) -> None:
        """From the reader thread into the loop."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile (service stopping)
            loop.call_soon_threadsafe(self._events.put_nowait, (incarnation, message))

    async def _start_worker(self) -> None:
        self._incarnation += 1
        process = WorkerProcess(
            self._incarnation, self._post, self.settings.nice, self.settings.progress_interval_s
        )
        await asyncio.to_thread(process.start)
        self._worker = _Worker(process)
        self._worker_up.set()
        log.info("worker %d started (pid %s)", self._incarnation, process.pid)

    # what the API calls

    def enqueue(self, record: JobRecord) -> None:
        """A job was stored as queued: look at the queue now (it is the database's; any instance's
        dispatcher may take it)."""
        self._queued += 1
        self._wakeup.set()

    async def cancel(self, job_id: int) -> JobRecord | None:
        """Cancel a queued or running job; returns the job as it is now (a running job is still running
        until its worker confirms), or None when there is no such job."""
        record = await asyncio.to_thread(self.store.get, job_id)
        if record is None or record.status.finished:
            return record
        current = self._current
        if current is not None and current.job_id == job_id:
            self._request_cancel(current)
            return record
        if await asyncio.to_thread(self.store.cancel, job_id, "cancelled before it ran"):
            self._queued = max(0, self._queued - 1)
            record = await asyncio.to_thread(self.store.get, job_id)
            if record is not None:
                self.broker.publish(JobFinishedEvent(job_id, record))
            return record
        # running: here (it went from queued to running meanwhile; the dispatcher passes the request on),
        # or on another instance, which sees the request at its next lease renewal
        self._cancel_requests.add(job_id)
        await asyncio.to_thread(self.queue.request_cancel, job_id)
        return await asyncio.to_thread(self.store.get, job_id)

    def runs_here(self, job_id: int) -> bool:
        """The job is this instance's current one (its events come through this broker)."""
        current = self._current
        return current is not None and current.job_id == job_id

    def live_progress(self, job_id: int) -> Progress | None:
        current = self._current
        return current.progress if current is not None and current.job_id == job_id else None

    def status(self) -> ManagerStatus:
        """In memory only: cheap enough for a status endpoint polled while a job runs."""
        worker, current = self._worker, self._current
        current = None if current is None or current.finishing else current
        return ManagerStatus(
            worker_alive=worker is not None and worker.process.alive,
            worker_ready=worker is not None and worker.ready,
            worker_pid=worker.process.pid if worker is not None else None,
            worker_restarts=self.restarts,
            queue_length=self._queued,
            current_job_id=current.job_id if current else None,
            current_kind=current.kind if current else None,
            current_progress=current.progress if current else None,
        )

    # dispatcher

    async def _next(self) -> JobRecord:
        """The next job, claimed from the shared queue (running here from now on)."""
        while True:
            self._wakeup.clear()
            try:
                record = await asyncio.to_thread(self.queue.claim_next)
            except Exception:  # the database away for a moment: try again at the next look
                log.exception("could not look at the job queue")
                record = None
            if record is not None:
                self._queued = max(0, self._queued - 1)
                return record
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._wakeup.wait(), self.settings.poll_s)

    async def _dispatch(self) -> None:
        assert self._loop is not None
        while True:
            record = await self._next()
            job_id = record.id
            # from here to the send no job is invisible: it is `current` as soon as it left the queue
            current = _Current(job_id, record.kind, 0, self._loop.create_future())
            self._current = current
            self.broker.publish(JobStateEvent(job_id, record))
            await self._worker_up.wait()
            assert self._worker is not None
            process = self._worker.process
            current.incarnation = process.incarnation  # the worker it is sent to, no await in between
            process.send(
                RunJob(
                    job_id,
                    record.kind,
                    record.recording_path,
                    record.vehicle_path,
                    record.output_dir,
                    record.options,
                )
            )  # if it cannot be sent, the worker is dead and the pump will say so
            if current.cancel_requested or job_id in self._cancel_requests:
                self._cancel_requests.discard(job_id)
                current.cancel_requested = True
                self._send_cancel(current)
            await current.done

    def _request_cancel(self, current: _Current) -> None:
        self._cancel_requests.discard(current.job_id)
        if current.cancel_requested:
            return
        current.cancel_requested = True
        if current.incarnation:  # else the dispatcher sends the cancel right after the job
            self._send_cancel(current)

    def _send_cancel(self, current: _Current) -> None:
        if self._worker is None:
            return
        self._worker.process.send(CancelJob(current.job_id))
        assert self._loop is not None
        self._kill_timer = self._loop.call_later(
            self.settings.cancel_grace_s, self._kill_if_still_running, current.job_id, current.incarnation
        )

    def _kill_if_still_running(self, job_id: int, incarnation: int) -> None:
        current, worker = self._current, self._worker
        if current is None or current.job_id != job_id or worker is None:
            return
        if worker.process.incarnation == incarnation:
            log.warning(
                "job %d did not stop within %.1f s of its cancel; killing the worker",
                job_id,
                self.settings.cancel_grace_s,
            )
            worker.process.kill()

    # leases

    async def _keep(self) -> None:
        """Every third of the lease: renew the running job's claim (and hear a cancel asked on another
        instance), take back jobs whose instance died, count the queue."""
        while True:
            await asyncio.sleep(self.settings.lease_s / 3)
            try:
                await self._keep_once()
            except Exception:  # the database away for a moment: the next round tries again
                log.exception("lease upkeep failed")

    async def _keep_once(self) -> None:
        current = self._current
        if current is not None:
            renewal = await asyncio.to_thread(self.queue.renew, current.job_id)
            if not renewal.held:
                log.warning(
                    "job %d: this instance lost its claim (lease ran out); stopping it here", current.job_id
                )
                self._request_cancel(current)
            elif renewal.cancel_requested:
                self._request_cancel(current)
        reclaimed = await asyncio.to_thread(self.queue.reclaim_expired)
        for job_id in reclaimed.requeued:
            log.warning("job %d: its instance stopped renewing its claim; back in the queue", job_id)
        self._queued = await asyncio.to_thread(self.queue.queued_count)
        if self._queued:
            self._wakeup.set()

    # worker messages

    async def _pump(self) -> None:
        while True:
            incarnation, message = await self._events.get()
            try:
                await self._handle(incarnation, message)
            except Exception:  # the pump must survive anything, e.g. a database hiccup
                log.exception("while handling %s from worker %d", type(message).__name__, incarnation)

    async def _handle(self, incarnation: int, message: FromWorker | WorkerExited) -> None:
        worker = self._worker
        if worker is None or incarnation != worker.process.incarnation:
            return  # from a worker already replaced
        if isinstance(message, WorkerExited):
            await self._worker_died(worker, message.exitcode)
            return
        if isinstance(message, WorkerReady):
            worker.ready = True
            return
        current = self._current
        if current is None or message.job_id != current.job_id:
            log.warning(
                "worker message %s for job %s, which is not running",
                type(message).__name__,
                getattr(message, "job_id", None),
            )
            return
        if isinstance(message, JobStarted):
            current.started = True
        elif isinstance(message, JobProgress):
            current.progress = message.progress
            self.broker.publish(JobProgressEvent(current.job_id, message.progress))
            now = time.monotonic()
            if now - current.persisted_at >= self.settings.persist_interval_s:
                current.persisted_at = now
                await asyncio.to_thread(
                    self.store.set_progress, current.job_id, message.progress.as_dict(), self.queue.instance
                )
        elif isinstance(message, JobSucceeded):
            await self._finish(
                current, JobStatus.SUCCEEDED, result=message.result, artefacts=message.artefacts
            )
        elif isinstance(message, JobFailed):
            await self._finish(current, JobStatus.FAILED, reason=message.reason)
        elif isinstance(message, JobCancelled):
            await self._finish(current, JobStatus.CANCELLED, reason="cancelled")

    async def _finish(
        self,
        current: _Current,
        status: JobStatus,
        *,
        result: JsonObject | None = None,
        artefacts: dict[str, str] | None = None,
        reason: str | None = None,
    ) -> None:
        """Write the outcome, then tell the listeners (so that whoever hears it reads it back). Whatever
        happens to the writing, the dispatcher moves on to the next job."""
        progress = current.progress.as_dict() if current.progress is not None else None
        job_id = current.job_id
        current.finishing = True
        if self._kill_timer is not None:
            self._kill_timer.cancel()
            self._kill_timer = None
        try:
            if status is JobStatus.SUCCEEDED:
                if self.completing is not None:
                    result = self.completing(current.kind, result or {})
                written = await asyncio.to_thread(
                    self.store.succeed, job_id, result or {}, artefacts or {}, progress, self.queue.instance
                )
            elif status is JobStatus.FAILED:
                written = await asyncio.to_thread(
                    self.store.fail, job_id, reason or "failed", progress, self.queue.instance
                )
            else:
                written = await asyncio.to_thread(
                    self.store.cancel,
                    job_id,
                    reason or "cancelled",
                    running=True,
                    progress=progress,
                    owner=self.queue.instance,
                )
            ran_s = time.monotonic() - current.dispatched_at
            if not written:  # its end is the new owner's to write and to log (once, there)
                log.warning(
                    "job %d %s here, but its claim was taken over meanwhile: not written",
                    job_id,
                    status.value,
                )
            else:
                why = f": {reason}" if reason else ""
                log.info("job %d (%s) %s after %.1f s%s", job_id, current.kind, status.value, ran_s, why)
                if self.on_finished is not None:
                    self.on_finished(current.kind, status.value, ran_s)
            record = await asyncio.to_thread(self.store.get, job_id)
            if record is not None:
                self.broker.publish(JobFinishedEvent(job_id, record))
        finally:
            self._current = None
            if not current.done.done():
                current.done.set_result(None)

    async def _worker_died(self, worker: _Worker, exitcode: int | None) -> None:
        self._worker_up.clear()
        how = describe_exit(exitcode)
        log.warning("worker %d (pid %s) exited: %s", worker.process.incarnation, worker.process.pid, how)
        current = self._current
        if current is not None and current.incarnation == worker.process.incarnation:
            if current.cancel_requested:
                await self._finish(current, JobStatus.CANCELLED, reason="cancelled (its worker was stopped)")
            elif not current.started:  # the worker never took it: not the job's fault, run it again
                try:
                    await asyncio.to_thread(self.store.requeue, current.job_id, self.queue.instance)
                    self._queued += 1
                    self._wakeup.set()
                finally:
                    self._current = None
                    current.done.set_result(None)
            else:
                reason = f"the worker process died while the job ran ({how}); the worker was restarted"
                await self._finish(current, JobStatus.FAILED, reason=reason)
        lived = time.monotonic() - worker.started_at
        self._quick_deaths = self._quick_deaths + 1 if lived < QUICK_DEATH_S else 0
        if self._quick_deaths > 1:  # back off only when workers keep dying straight after their start
            await asyncio.sleep(min(MAX_BACKOFF_S, 2.0 ** (self._quick_deaths - 2)))
        self.restarts += 1
        while True:
            try:
                await self._start_worker()
                return
            except Exception:  # e.g. out of processes or memory: keep trying, jobs wait in the queue
                log.exception("could not start a worker; trying again in %.0f s", MAX_BACKOFF_S)
                await asyncio.sleep(MAX_BACKOFF_S)
