"""The Dask worker plugin of `shockbench reanalyse` (its own module: it imports dask.distributed, which the
[cluster] extra brings, only when a cluster is used)."""

from __future__ import annotations

import gc
from typing import Any

from distributed.core import Status
from distributed.diagnostics.plugin import WorkerPlugin

from service.reanalyse.task import warm_up

CLOSING = frozenset({Status.closing, Status.closing_gracefully, Status.closed})


class WorkerSetup(WorkerPlugin):
    """One BLAS thread and the estimator loaded when a worker joins (task.warm_up), on the local cluster's
    workers and on those of a scheduler given by address alike: no task pays for it. When the worker
    closes, its objects are frozen for the garbage collector (gc.freeze): its process ends next, and
    Python's shutdown would otherwise go over every object the estimator, numpy and Dask hold, about 0.1 s
    of the 0.2-0.3 s the local cluster took to stop (as `shockbench identify` does, service.cli.main)."""

    name = "shockbench-reanalyse-setup"
    idempotent = True

    def setup(self, worker: Any) -> None:
        warm_up()

    def teardown(self, worker: Any) -> None:
        if worker.status in CLOSING:  # not when the plugin alone is removed from a worker that goes on
            gc.freeze()
