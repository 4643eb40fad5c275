"""The local cluster's workers forked from a warm, single-threaded server (multiprocessing's forkserver),
started before the client imports Dask, so that the two imports run side by side on two cores.

Why: a local cluster's start is paid once by every run, so it bounds how much faster two workers are than
one (issue 33). With Dask's default start (`spawn`) each worker is a fresh interpreter that imports Dask
and the estimator only after the client has imported Dask: the client's import (about 0.3 s) and the
workers' (about 0.35 s) follow each other. Here the server imports both while the client imports Dask, and
each worker is a fork of it that is ready at once (a 2-worker cluster up in about 0.6 s instead of 0.85 s,
BENCHMARKS.md).

Why it is safe where forking the client was not (docs/benchmarks-history.md): the server runs no thread of
its own (Dask's event loop and the database pool live in the client), so a fork cannot copy a lock another
thread holds. Its BLAS is set to one thread before numpy loads in it (the workers are forked, not spawned,
so the nanny's environment for a spawned worker would come too late), and its modules are those on disk
when it starts. Where the platform has no forkserver (Windows) the cluster spawns its workers as before.
"""

from __future__ import annotations

import multiprocessing
import os
from importlib.util import find_spec
from multiprocessing import forkserver

from service.reanalyse.task import BLAS_THREADS

PRELOAD = ("distributed", "service.reanalyse.worker_preload")
"""What the server imports once for every worker: Dask's worker and what an analysis needs."""
METHOD = "forkserver"


def start_forkserver() -> bool:
    """Start the forkserver (if it is not running yet) with PRELOAD, BLAS at one thread in it; True when
    the local cluster can fork its workers from it (Dask installed, a POSIX platform)."""
    if METHOD not in multiprocessing.get_all_start_methods() or find_spec("distributed") is None:
        return False
    multiprocessing.get_context(METHOD).set_forkserver_preload(list(PRELOAD))
    saved = {name: os.environ.get(name) for name in BLAS_THREADS}
    os.environ.update(BLAS_THREADS)  # the server inherits this process's environment when it starts
    try:
        forkserver.ensure_running()
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
    return True
