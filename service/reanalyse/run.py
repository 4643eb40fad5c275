"""The client side of `shockbench reanalyse`: decide what is left to do, send it to dask.distributed (a
LocalCluster of worker processes with one thread each, or a running scheduler by address) in batches that
carry the recordings' bytes (task.py: no shared folder), store each result as it arrives (result files
in OUT, and with a database a stored run: service.store.reanalysis_runs), show the progress and write the
summary table.

Why Dask: issue 18 names dask.distributed; it starts local worker processes and connects to a cluster with
the same client code, retries a task whose worker died, and marks one that kills its workers again and
again as failed (KilledWorker) instead of hanging: a batch that fails so is split into single recordings
and sent again, so one bad recording is one failed recording, not a failed batch or run.

Batches are submitted a few per worker at a time (IN_FLIGHT_PER_WORKER), not all at once: the client reads
a recording's bytes only shortly before a worker needs them, so an archive of any size fits in memory.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from estimator.errors import UserError, one_line
from service.extras import extra_needed
from service.reanalyse.forkserver import METHOD as FORK_METHOD
from service.reanalyse.forkserver import start_forkserver
from service.reanalyse.results import Done, save, stored, summary_row, write_summary
from service.reanalyse.sources import Item, input_digest
from service.reanalyse.task import (
    BLAS_THREADS,
    Analysis,
    AnalysisOptions,
    Outcome,
    Payload,
    Task,
    Work,
    payload_of,
    run_batch,
)
from service.store.reanalysis_runs import RunStore, Written

if TYPE_CHECKING:
    from dask.distributed import Client

    from service.store.database import Database


class SchedulerError(UserError, ValueError):
    """--scheduler is not an address Dask understands; one line."""


DASK_NEEDED_FOR = "shockbench reanalyse (on dask.distributed)"
"""What needs the [cluster] extra, in the one line that says it is missing (service.extras)."""
CONNECT_TIMEOUT = "10s"
"""How long to try a scheduler given by address before a one-line error."""
ONE_BLAS_THREAD = {
    f"distributed.nanny.pre-spawn-environ.{name}": value for name, value in BLAS_THREADS.items()
}
"""The local cluster's workers start with one BLAS thread (set before numpy loads); those of a scheduler
given by address are limited when they join (task.warm_up)."""
QUIET_CLUSTER = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}
"""What the local cluster's scheduler, nannies and workers do beside the work, cut down: the workers'
statistical profiler (every 10 ms, on the worker's event loop thread, which takes the GIL from the analysis
for it), every server's event-loop health tick (every 20 ms), the memory monitor (every 100 ms, a psutil call
per worker in the client's process) and the system monitor (every 500 ms). They serve the dashboard's
plots and warnings only, and they ran on the same cores as the analyses: 5 ms a recording of the client
process's CPU (12 against 7 ms with them cut down, 100 recordings on 2 workers)."""
MAX_BATCH = 8
"""Recordings per task at most: Dask's per-task cost (about 7 ms of the client's and the local scheduler's
CPU, taken from the workers' cores) shared, the last tasks short all the same (batched). 100 recordings on
2 workers: 19 tasks and 4.0 ms of client CPU a recording, against 29 tasks and 4.7 ms with at most 4."""
IN_FLIGHT_PER_WORKER = 3
"""Batches submitted per worker ahead of the results."""


def batch_size(recordings: int, workers: int) -> int:
    """Recordings per task: about six tasks per worker, at most MAX_BATCH."""
    return max(1, min(MAX_BATCH, recordings // max(1, 6 * workers)))


def batched(work: Sequence[Any], size: int, workers: int) -> list[list[Any]]:
    """`work` in batches of `size`, shorter towards the end: each batch at most a (2·workers)-th of what is
    left, down to single recordings, so the workers end together instead of one finishing a whole batch
    while the others wait, in fewer tasks than single recordings all along the end (a task costs the
    client and the scheduler about 7 ms of CPU on the workers' cores)."""
    batches: list[list[Any]] = []
    start = 0
    while start < len(work):
        left = len(work) - start
        step = max(1, min(size, math.ceil(left / (2 * max(1, workers)))))
        batches.append(list(work[start : start + step]))
        start += step
    return batches


@dataclass(frozen=True)
class RunSettings:
    """out: the output folder (None: results in the database's run only); scheduler: a running
    scheduler's address (tcp://HOST:PORT), None for a LocalCluster of `workers` processes; database: where
    the recordings of items with a sha256 are, and where the run is stored; batch: recordings per task
    (None: batch_size)."""

    out: Path | None
    analyses: tuple[Analysis, ...] = (Analysis.IDENTIFY,)
    options: AnalysisOptions = field(default_factory=AnalysisOptions)
    scheduler: str | None = None
    workers: int = 2
    database: Database | None = None
    batch: int | None = None


@dataclass(frozen=True)
class RunReport:
    rows: list[dict[str, str]]
    """The summary's rows, in the order of the items."""
    summary: Path | None
    ran: int
    """Analyses run now (the rest were skipped: done before on the same input)."""
    skipped: int
    run_id: int | None = None
    """The stored run (with a database)."""

    @property
    def failed(self) -> int:
        return sum(row["status"] != "ok" for row in self.rows)


def dashboard_link(client: Client) -> str | None:
    """The Dask dashboard's address when the scheduler serves one (it needs bokeh where the scheduler
    runs: the address answers only then), else None."""
    import httpx

    link = client.dashboard_link
    try:
        answered = httpx.get(link, timeout=2.0, follow_redirects=True).status_code == 200
    except (httpx.HTTPError, ValueError):
        return None
    return link if answered else None


def _bokeh_installed() -> bool:
    from importlib.util import find_spec

    return find_spec("bokeh") is not None


@contextmanager
def dask_client(settings: RunSettings) -> Iterator[Client]:
    """A client of the scheduler at settings.scheduler, or of a LocalCluster of settings.workers processes
    with one thread each (the estimator is single-threaded numpy: processes, not threads, run in parallel);
    its workers set up by WorkerSetup; a LocalCluster's forked from a warm server started first
    (forkserver.py), where the platform has one."""
    forked = settings.scheduler is None and start_forkserver()  # before Dask's import: side by side
    with extra_needed("cluster", DASK_NEEDED_FOR):
        import dask
        from dask.distributed import Client, LocalCluster

        from service.reanalyse.worker_setup import WorkerSetup

    if settings.scheduler is not None:
        try:
            client = Client(settings.scheduler, timeout=CONNECT_TIMEOUT)  # OSError when nobody answers
        except ValueError as exc:
            raise SchedulerError(f"--scheduler {settings.scheduler}: {one_line(exc)}") from None
        with client:
            client.register_plugin(WorkerSetup())
            yield client
        return
    start = {"distributed.worker.multiprocessing-method": FORK_METHOD} if forked else {}
    with (
        dask.config.set({**ONE_BLAS_THREAD, **QUIET_CLUSTER, **start}),
        LocalCluster(
            n_workers=settings.workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0" if _bokeh_installed() else None,
            silence_logs=logging.ERROR,
        ) as cluster,
        Client(cluster) as client,
    ):
        client.register_plugin(WorkerSetup())
        yield client


def _failed(work: Work, exc: BaseException) -> list[Outcome]:
    reason = f"worker failed: {type(exc).__name__}: {one_line(exc)}"
    return [Outcome(task, None, reason, 0.0) for task in work.tasks]


def run_on_dask(
    client: Client,
    batches: Sequence[Sequence[tuple[Item, tuple[Task, ...]]]],
    fetch: Callable[[Sequence[Item]], list[Payload | BaseException]],
) -> Iterator[list[Outcome]]:
    """The outcomes of each batch as it finishes; a batch's payloads fetched just before it is submitted.
    A batch whose worker failed under it (KilledWorker after the scheduler's retries) is sent again one
    recording at a time; a single recording that fails so is a failed outcome naming the exception. A
    recording whose payload cannot be read fails without a worker."""
    with extra_needed("cluster", DASK_NEEDED_FOR):
        from dask.distributed import as_completed

    workers = max(1, len(client.scheduler_info().get("workers", {})))
    queue = list(batches)
    running = as_completed()
    sent: dict[str, list[Work]] = {}

    def submit(works: list[Work]) -> None:
        if works:
            future = client.submit(run_batch, works, pure=False)
            sent[future.key] = works
            running.add(future)

    def submit_next() -> Iterator[list[Outcome]]:
        while queue:
            batch = queue.pop(0)
            works, unread = [], []
            for (_item, tasks), payload in zip(batch, fetch([item for item, _ in batch]), strict=True):
                if isinstance(payload, BaseException):
                    unread += [Outcome(task, None, one_line(payload), 0.0) for task in tasks]
                else:
                    works.append(Work(payload, tasks))
            if unread:
                yield unread
            if works:
                submit(works)
                return

    for _ in range(IN_FLIGHT_PER_WORKER * workers):
        yield from submit_next()
    for future in running:
        works = sent.pop(future.key)
        try:
            outcomes = future.result()
        except Exception as exc:
            if len(works) > 1:
                for work in works:
                    submit([work])
                outcomes = []
            else:
                outcomes = _failed(works[0], exc)
        future.release()
        if outcomes:
            yield outcomes
        yield from submit_next()


def _fetcher(database: Database | None) -> Callable[[Sequence[Item]], list[Payload | BaseException]]:
    """The payloads of a batch's items (or why one cannot be read): stored recordings' bytes as stored,
    in one query, or a folder's files read now."""
    from service.store.recordings import ZLIB, RecordingStore

    store = RecordingStore(database) if database is not None else None

    def fetch(items: Sequence[Item]) -> list[Payload | BaseException]:
        stored = [item.sha256 for item in items if item.sha256 is not None]
        found = store.shipped_many(stored) if store is not None and stored else {}
        payloads: list[Payload | BaseException] = []
        for item in items:
            try:
                if item.sha256 is None:
                    payloads.append(payload_of(item))
                elif item.sha256 in found:
                    compression, data, vehicle_text = found[item.sha256]
                    payloads.append(
                        Payload(item.recording.name, data, compression == ZLIB, vehicle_text, None)
                    )
                else:
                    payloads.append(KeyError(f"recording {item.sha256[:12]} is not stored in the database"))
            except (UserError, OSError) as exc:
                payloads.append(exc)
        return payloads

    return fetch


def reanalyse(
    items: Sequence[Item],
    settings: RunSettings,
    say: Callable[[str], None],
    progress: Callable[[int, int, Outcome], None] | None = None,
    on_client: Callable[[Client], None] | None = None,
) -> RunReport:
    """Analyse the items not done before, store each result, write the summary. `say` gets a line at the
    start, `progress` each finished analysis with its number and the total (default: one line each to
    `say`), `on_client` the Dask
    client once it is up (the dashboard's address)."""
    from service.reanalyse.progress import outcome_line

    out = settings.out
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    done: dict[str, dict[Analysis, Done]] = {item.name: {} for item in items}
    digests: dict[str, str] = {}
    todo: dict[str, list[Task]] = {}
    for item in items:
        reason = item.problem
        if reason is None:
            try:
                digests[item.name] = input_digest(item)
            except OSError as exc:
                reason = one_line(exc)
        for analysis in settings.analyses:
            if reason is not None:
                done[item.name][analysis] = Done(None, reason)
                continue
            before = stored(out, item, analysis, digests[item.name], settings.options) if out else None
            if before is not None:
                done[item.name][analysis] = before
            else:
                todo.setdefault(item.name, []).append(Task(item, analysis, settings.options))
    tasks = sum(len(t) for t in todo.values())
    skipped = sum(d.document is not None for per_item in done.values() for d in per_item.values())
    runs, run_id = _begin_run(settings, sum(item.sha256 is not None for item in items))
    where = settings.scheduler or f"a local cluster of {settings.workers} worker process(es)"
    stored_as = f" (run {run_id})" if runs is not None else ""
    say(
        f"{len(items)} recording(s): {tasks} analysis(es) to run on {where}{stored_as}, "
        f"{skipped} done before (skipped)"
    )
    if runs is not None:  # what failed before any worker (unreadable) is stored too
        runs.record_many(
            run_id,
            [
                Written(item.sha256, analysis.value, None, d.reason, 0.0)
                for item in items
                if item.sha256 is not None
                for analysis, d in done[item.name].items()
                if d.document is None
            ],
        )
    if tasks:
        work = [(tasks_[0].item, tuple(tasks_)) for tasks_ in todo.values()]
        size = settings.batch or batch_size(len(work), settings.workers)
        batches = batched(work, size, settings.workers)
        with dask_client(settings) as client:
            if on_client is not None:
                on_client(client)
            number = 0
            for outcomes in run_on_dask(client, batches, _fetcher(settings.database)):
                for outcome in outcomes:
                    item = outcome.task.item
                    done[item.name][outcome.task.analysis] = save(out, outcome, digests[item.name])
                if runs is not None:  # a batch's results in one transaction
                    runs.record_many(run_id, [_written(o) for o in outcomes if o.task.item.sha256])
                for outcome in outcomes:
                    number += 1
                    if progress is not None:
                        progress(number, tasks, outcome)
                    else:
                        say(outcome_line(number, tasks, outcome))
    if runs is not None:
        runs.finish(run_id)
    rows = [summary_row(item, {a: done[item.name][a] for a in settings.analyses}) for item in items]
    summary = write_summary(out, rows, Analysis.DIAGNOSE in settings.analyses) if out else None
    return RunReport(rows, summary, tasks, skipped, run_id if runs is not None else None)


def _written(outcome: Outcome) -> Written:
    task = outcome.task
    assert task.item.sha256 is not None
    return Written(task.item.sha256, task.analysis.value, outcome.result, outcome.reason, outcome.seconds)


def _begin_run(settings: RunSettings, recordings: int) -> tuple[RunStore | None, int]:
    """(RunStore, the new run's id) with a database, else (None, 0). `recordings`: the stored ones
    (a complete sweep whose recording is not stored is in the summary, not in the run)."""
    if settings.database is None:
        return None, 0
    from service.version import shockbench_version

    runs = RunStore(settings.database)
    options = {"analyses": [a.value for a in settings.analyses], **settings.options.as_dict()}
    return runs, runs.begin(shockbench_version(), options, recordings)
