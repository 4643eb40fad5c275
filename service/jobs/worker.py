"""The worker process: runs one job at a time (identification, later diagnosis) away from the service's
event loop, and reports over its pipe.

The service spawns it (multiprocessing, spawn context: a fresh interpreter, no copied locks or threads),
owns it and restarts it when it dies. Two threads: the main thread runs jobs from a local queue; a listener
thread reads the pipe, queues RunJob, and turns CancelJob into the running job's cancel Event (the DE
stops after its current generation). On Shutdown, or when the pipe closes (the service died), the worker
exits at once: it holds nothing to save.

The worker lowers its own scheduling priority (nice) so that on a small bench PC the service's event loop
stays responsive while DE uses a core.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import queue
import secrets
import signal
import sys
import threading
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path

from estimator.errors import UserError, one_line
from service.jobs.messages import (
    CancelJob,
    FromWorker,
    JobCancelled,
    JobFailed,
    JobProgress,
    JobStarted,
    JobSucceeded,
    RunJob,
    Shutdown,
    WorkerReady,
)


class _Cancellation:
    """Cancel requests, whether they arrive before or while their job runs."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._current: tuple[int, threading.Event] | None = None
        self._early: set[int] = set()

    def begin(self, job_id: int) -> threading.Event:
        event = threading.Event()
        with self._lock:
            if job_id in self._early:
                self._early.discard(job_id)
                event.set()
            self._current = (job_id, event)
        return event

    def end(self) -> None:
        with self._lock:
            self._current = None

    def cancel(self, job_id: int) -> None:
        with self._lock:
            if self._current is not None and job_id == self._current[0]:
                self._current[1].set()
            else:
                self._early.add(job_id)


def _without_paths(reason: str, job: RunJob) -> str:
    """The reason as viewers may read it: the job's files by their names, not their places on the server."""
    for path in (job.recording_path, job.vehicle_path, job.output_dir):
        reason = reason.replace(str(Path(path).parent) + os.sep, "").replace(str(path), Path(path).name)
    return reason


def _listen(conn: Connection, jobs: queue.Queue[RunJob], cancellation: _Cancellation) -> None:
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            os._exit(0)  # the service is gone: nobody to report to, and no orphan left behind
        if isinstance(message, RunJob):
            jobs.put(message)
        elif isinstance(message, CancelJob):
            cancellation.cancel(message.job_id)
        elif isinstance(message, Shutdown):  # nothing to save: the service puts a running job back in
            os._exit(0)  # its queue, and stopping now does not wait for a DE generation or an import


def run_job(
    job: RunJob, send: Callable[[FromWorker], None], cancel: threading.Event, progress_interval_s: float
) -> None:
    """Run one job and send exactly one outcome message. Bad input (a UserError) and a file gone or
    unreadable (OSError) become JobFailed with their one-line message. Anything else is a bug: its traceback
    goes to the worker's stderr (the service log) under a fresh error id, and the reason names that id
    (never the traceback)."""
    from daq.formats.recording_file import read_recording_file
    from service.jobs.context import JobContext, JobOutcome, ProgressReporter
    from service.jobs.kinds import kind_spec

    send(JobStarted(job.job_id))
    reporter = ProgressReporter(lambda p: send(JobProgress(job.job_id, p)), progress_interval_s)
    try:
        reporter.stage("reading input")
        spec = kind_spec(job.kind)
        module, _, function = spec.runner.partition(":")
        runner = getattr(importlib.import_module(module), function)
        recording = read_recording_file(job.recording_path)  # a sweep's HDF5 where acquisition wrote it
        companion_path = Path(job.vehicle_path)
        companion = spec.companion.read(companion_path.read_text(encoding="utf-8"), companion_path.name)
        vehicle = spec.companion.vehicle_of(companion)
        # the submit checks again (bounds, bandwidth, model): a job queued before a check existed, or
        # whose files changed on disk, fails here in words instead of deep in the estimator
        options = spec.options_model.model_validate(job.options)
        spec.check(options, recording, companion)
        output_dir = Path(job.output_dir)
        output_dir.mkdir(parents=True, exist_ok=True)
        if cancel.is_set():
            raise InterruptedError("cancelled before it started")
        context = JobContext(job.job_id, recording, vehicle, options, output_dir, cancel, reporter, companion)
        outcome: JobOutcome = runner(context)
        succeeded = JobSucceeded(job.job_id, outcome.result, outcome.artefacts)
        reporter.stage("done")
    except InterruptedError:
        send(JobCancelled(job.job_id))
    except (UserError, OSError) as exc:
        send(JobFailed(job.job_id, _without_paths(one_line(exc), job)))
    except Exception as exc:
        error_id = secrets.token_hex(6)
        print(f"error id {error_id}: unexpected error in job {job.job_id}", file=sys.stderr)
        traceback.print_exc(file=sys.stderr)
        reason = (
            f"internal error in the worker (error id {error_id}; the service log has the details under "
            f"that id): {type(exc).__name__}: {one_line(exc)}"
        )
        send(JobFailed(job.job_id, _without_paths(reason, job)))
    else:
        send(succeeded)


def worker_main(conn: Connection, nice: int = 0, progress_interval_s: float = 0.2) -> None:
    """Entry point of the worker process."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group: the service
    if nice:  # decides, and stops the worker itself
        with contextlib.suppress(OSError):
            os.nice(nice)
    lock = threading.Lock()

    def send(message: FromWorker) -> None:
        with lock:
            conn.send(message)

    jobs: queue.Queue[RunJob] = queue.Queue()
    cancellation = _Cancellation()
    threading.Thread(target=_listen, args=(conn, jobs, cancellation), name="pipe", daemon=True).start()
    from service.jobs.kinds import KINDS

    for spec in KINDS.values():  # load the estimator and matplotlib now, not in the first job
        for module in (*spec.preload, spec.runner.partition(":")[0]):
            importlib.import_module(module)
    from estimator.simulation_kernel import warm

    warm()  # the output-error kernel too (numba's cache load when no extension is built: 1-3 s)
    send(WorkerReady(os.getpid()))
    while True:  # until the service says Shutdown or goes away (the listener ends the process)
        job = jobs.get()
        cancel = cancellation.begin(job.job_id)
        try:
            run_job(job, send, cancel, progress_interval_s)
        finally:
            cancellation.end()
