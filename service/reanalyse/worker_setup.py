"""The Dask worker plugin of `shockbench reanalyse` (its own module: it imports dask.distributed, which the
[cluster] extra brings, only when a cluster is used)."""

from __future__ import annotations

import gc
from typing import Any

from distributed.core import Status
from distributed.diagnostics.plugin import WorkerPlugin

from service.allocator import keep_freed_memory
from service.reanalyse.task import warm_up

CLOSING = frozenset({Status.closing, Status.closing_gracefully, Status.closed})


class WorkerSetup(WorkerPlugin):
    """One BLAS thread, the estimator loaded (task.warm_up) and glibc's allocator keeping freed memory as
    `shockbench identify` has it (service.allocator: without it every array above 128 kB was a fresh mapping,
    about 9 000 page faults and 17 ms of system time a 12 s recording; Dask's nannies start workers with
    MALLOC_TRIM_THRESHOLD_=65536, which made an identification take 2.2 times the CPU, and these settings
    override it) when a worker joins, on the local cluster's workers and on those of a scheduler given by
    address alike, however they were started: no task pays for it. When the worker
    closes, its objects are frozen for the garbage collector (gc.freeze): its process ends next, and
    Python's shutdown would otherwise go over every object the estimator, numpy and Dask hold, about 0.1 s
    of the 0.2-0.3 s the local cluster took to stop (as `shockbench identify` does, service.cli.main)."""

    name = "shockbench-reanalyse-setup"
    idempotent = True

    def setup(self, worker: Any) -> None:
        keep_freed_memory()
        warm_up()

    def teardown(self, worker: Any) -> None:
        if worker.status in CLOSING:  # not when the plugin alone is removed from a worker that goes on
            gc.freeze()
