"""The Dask worker plugin of `shockbench reanalyse` (its own module: it imports dask.distributed, which the
[cluster] extra brings, only when a cluster is used)."""

from __future__ import annotations

from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from service.reanalyse.task import warm_up


class WorkerSetup(WorkerPlugin):
    """One BLAS thread and the estimator loaded when a worker joins (task.warm_up), on the local cluster's
    workers and on those of a scheduler given by address alike: no task pays for it."""

    name = "shockbench-reanalyse-setup"
    idempotent = True

    def setup(self, worker: Any) -> None:
        warm_up()
