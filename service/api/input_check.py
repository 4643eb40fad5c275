"""Reading and checking a job's input files in a process of their own, so that the event loop never waits.

A 60 MB recording CSV takes the pure-Python reader (daq.formats.recording_csv) some seconds, and turning its
rows into an array holds the interpreter lock for about a second at a time. In a thread of the service that
stalls every request (GET /status waited 3.8 s behind one upload). Here the files are read and checked by
the same functions in one spawned helper process (`InputChecker`), which answers only "fine" or the 422
(message, field): nothing large crosses the pipe, and the service's interpreter lock stays free.

The checker is shared by the apps of one process (tests run several): `start` and `close` count users. A
helper process that died (killed, out of memory) is replaced on the next check.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import multiprocessing.connection
import os
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from service.jobs.context import InputError

log = logging.getLogger("shockbench.api")

Refusal = tuple[str, str | None, str | None]
"""(message, field, recording error class) of an input the checks refuse: an InputError in the caller's
process, or the HDF5 recording's own error class named (RecordingGapError ...) so its status code stays."""


def inspect_inputs(
    kind: str,
    options: dict[str, Any],
    recording_path: str,
    recording_name: str,
    vehicle_path: str,
    vehicle_name: str,
) -> Refusal | None:
    """Runs in the helper process: read both files and run the kind's checks; None when the job can run."""
    from daq.storage.hdf5_recording import RecordingFileError
    from estimator.errors import UserError, one_line
    from service.api.intake import check_files
    from service.jobs.kinds import kind_spec

    spec = kind_spec(kind)
    try:
        check_files(
            spec,
            spec.options_model.model_validate(options),
            Path(recording_path),
            recording_name,
            Path(vehicle_path),
            vehicle_name,
        )
    except RecordingFileError as exc:
        return one_line(exc), exc.field, type(exc).__name__
    except UserError as exc:  # InputError mostly; any bad input is refused alike
        return one_line(exc), exc.field, None
    return None


CHECKER_NICE = 5
"""Added to the helper's nice value, as to the worker's: the event loop keeps priority over parsing."""


def _start_helper() -> None:
    """The helper process's initializer: a lower priority, and an end with the service. A service killed
    outright (SIGKILL, out of memory) cannot shut its pool down; without this the helper would stay behind
    as an orphan holding its memory, one more at every restart."""
    with contextlib.suppress(OSError):
        os.nice(CHECKER_NICE)
    parent = multiprocessing.parent_process()
    if parent is not None:
        threading.Thread(
            target=_exit_with, args=(parent.sentinel,), name="service-watch", daemon=True
        ).start()


def _exit_with(parent_sentinel: int) -> None:
    """Wait until the service process has ended, then end this one (the sentinel turns ready then)."""
    multiprocessing.connection.wait([parent_sentinel])
    os._exit(0)


def _warm_up() -> None:
    """Load the readers and the checks in the helper now, not in the first upload."""
    import service.api.intake
    import service.jobs.kinds  # noqa: F401


class InputChecker:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pool: ProcessPoolExecutor | None = None
        self._users = 0

    def start(self) -> None:
        """Start the helper process (blocking for the time its imports take: call it in a thread)."""
        with self._lock:
            self._users += 1
            pool = self._ensure_pool()
        pool.submit(_warm_up).result()

    def close(self) -> None:
        with self._lock:
            self._users = max(0, self._users - 1)
            pool, self._pool = (self._pool, None) if self._users == 0 else (None, self._pool)
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def _ensure_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                max_workers=1, mp_context=multiprocessing.get_context("spawn"), initializer=_start_helper
            )
        return self._pool

    def _submit(self, *args: Any) -> Future[Refusal | None]:
        with self._lock:
            return self._ensure_pool().submit(inspect_inputs, *args)

    def check(
        self,
        kind: str,
        options: dict[str, Any],
        recording: tuple[Path, str],
        vehicle: tuple[Path, str],
    ) -> None:
        """InputError (naming the field) when the input cannot run. Blocking: call it in a thread."""
        args = (kind, options, str(recording[0]), recording[1], str(vehicle[0]), vehicle[1])
        try:
            refusal = self._submit(*args).result()
        except BrokenProcessPool:
            log.warning("the input checker process died; starting a new one")
            with self._lock:
                self._pool = None
            refusal = self._submit(*args).result()
        if refusal is not None:
            message, field, recording_error = refusal
            if recording_error is not None:
                from daq.storage import hdf5_recording

                raise getattr(hdf5_recording, recording_error)(message, field=field)
            raise InputError(field, message)


CHECKER = InputChecker()
"""The checker of this process (service.api.intake submits to it; the app's lifespan starts and closes it)."""
