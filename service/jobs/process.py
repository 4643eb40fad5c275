"""The service's handle on one worker process ("incarnation"): spawn it, send it messages, learn of its
messages and of its death.

A reader thread blocks on the pipe and hands every message to `post` (which the job manager makes
thread-safe into its event loop); when the pipe closes it reaps the process and posts WorkerExited with the
exit code. Each incarnation has its own pipe, so a worker killed in the middle of a send can never leave a
lock or half a message behind for the next one.
"""

from __future__ import annotations

import multiprocessing
import signal
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess

from service.jobs.messages import FromWorker, Shutdown, ToWorker, WorkerExited
from service.jobs.worker import worker_main

Post = Callable[[int, FromWorker | WorkerExited], None]


def describe_exit(exitcode: int | None) -> str:
    """'exit code 1', 'killed by SIGKILL' ..."""
    if exitcode is None:
        return "exit status unknown"
    if exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exit code {exitcode}"


class WorkerProcess:
    def __init__(self, incarnation: int, post: Post, nice: int = 0, progress_interval_s: float = 0.2) -> None:
        self.incarnation = incarnation
        self._post = post
        self._nice = nice
        self._interval = progress_interval_s
        self._send_lock = threading.Lock()
        self._conn: Connection | None = None
        self.process: BaseProcess | None = None

    def start(self) -> None:
        """Spawn the process (blocking for a few milliseconds: call it from a thread)."""
        context = multiprocessing.get_context("spawn")
        ours, theirs = context.Pipe(duplex=True)
        self.process = context.Process(
            target=worker_main,
            args=(theirs, self._nice, self._interval),
            name=f"shockbench-worker-{self.incarnation}",
            daemon=True,  # never outlives the service
        )
        self.process.start()
        theirs.close()  # only the child holds its end: its death closes the pipe
        self._conn = ours
        threading.Thread(
            target=self._read,
            args=(ours, self.process),
            name=f"worker-{self.incarnation}-reader",
            daemon=True,
        ).start()

    def _read(self, conn: Connection, process: BaseProcess) -> None:
        while True:
            try:
                message = conn.recv()
            except (EOFError, OSError):
                break
            self._post(self.incarnation, message)
        process.join(timeout=10)
        self._post(self.incarnation, WorkerExited(self.incarnation, process.exitcode))

    @property
    def pid(self) -> int | None:
        return self.process.pid if self.process is not None else None

    @property
    def alive(self) -> bool:
        return self.process is not None and self.process.is_alive()

    def send(self, message: ToWorker) -> bool:
        """False when the worker can no longer be reached (its death is reported by the reader)."""
        if self._conn is None:
            return False
        try:
            with self._send_lock:
                self._conn.send(message)
        except (OSError, ValueError):
            return False
        return True

    def kill(self) -> None:
        if self.process is not None and self.process.is_alive():
            self.process.kill()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Ask the worker to exit (at once, even mid-job), kill it if it has not within the timeout."""
        if self.process is None:
            return
        self.send(Shutdown())
        self.process.join(timeout_s)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(timeout_s)
        if self._conn is not None:
            self._conn.close()
