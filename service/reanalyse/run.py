"""The client side of `shockbench reanalyse`: decide what is left to do (results.stored), send it to
dask.distributed (a LocalCluster of worker processes with one thread each, or a running scheduler by
address), store each result as it arrives (results.save: an interrupted run keeps what it finished), say
one line per finished analysis, and write the summary table.

Why Dask: issue 18 names dask.distributed; it starts local worker processes and connects to a cluster with
the same client code, retries a task whose worker died, and marks one that kills its workers again and
again as failed (KilledWorker) instead of hanging: here that is one failed recording, not a failed run.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from estimator.errors import UserError, one_line
from service.extras import extra_needed
from service.reanalyse.results import Done, save, stored, summary_row, write_summary
from service.reanalyse.sources import Item, input_digest
from service.reanalyse.task import Analysis, AnalysisOptions, Outcome, Task, run_task

if TYPE_CHECKING:
    from dask.distributed import Client


class SchedulerError(UserError, ValueError):
    """--scheduler is not an address Dask understands; one line."""


DASK_NEEDED_FOR = "shockbench reanalyse (on dask.distributed)"
"""What needs the [cluster] extra, in the one line that says it is missing (service.extras)."""
CONNECT_TIMEOUT = "10s"
"""How long to try a scheduler given by address before a one-line error."""
NO_MALLOC_TRIM = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
"""Dask's nannies start workers with MALLOC_TRIM_THRESHOLD_=65536 (to give memory back to the system
sooner); setting it turns off glibc's adaptive mmap threshold, so every array of the estimator above 128 kB
is a fresh mmap whose pages fault in zeroed: an identification took 2.2 times the CPU time (30 short
recordings: 6.1 s against 2.8 s of thread CPU, same with the variable set in a plain loop). The local
cluster leaves it unset; workers of a scheduler given by address are started by whoever runs them, who
should do the same (this key set to null in their Dask configuration; BENCHMARKS.md, "Archive
re-analysis")."""


@dataclass(frozen=True)
class RunSettings:
    """out: the output folder; scheduler: a running scheduler's address (tcp://HOST:PORT), None for a
    LocalCluster of `workers` processes."""

    out: Path
    analyses: tuple[Analysis, ...] = (Analysis.IDENTIFY,)
    options: AnalysisOptions = field(default_factory=AnalysisOptions)
    scheduler: str | None = None
    workers: int = 2


@dataclass(frozen=True)
class RunReport:
    rows: list[dict[str, str]]
    """The summary's rows, in the order of the items."""
    summary: Path
    ran: int
    """Analyses run now (the rest were skipped: done before on the same input)."""
    skipped: int

    @property
    def failed(self) -> int:
        return sum(row["status"] != "ok" for row in self.rows)


@contextmanager
def dask_client(settings: RunSettings) -> Iterator[Client]:
    """A client of the scheduler at settings.scheduler, or of a LocalCluster of settings.workers processes
    with one thread each (the estimator is single-threaded numpy: processes, not threads, run in parallel)."""
    with extra_needed("cluster", DASK_NEEDED_FOR):
        import dask
        from dask.distributed import Client, LocalCluster

    if settings.scheduler is not None:
        try:
            client = Client(settings.scheduler, timeout=CONNECT_TIMEOUT)  # OSError when nobody answers
        except ValueError as exc:
            raise SchedulerError(f"--scheduler {settings.scheduler}: {one_line(exc)}") from None
        with client:
            yield client
        return
    with (
        dask.config.set(NO_MALLOC_TRIM),
        LocalCluster(
            n_workers=settings.workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


def run_on_dask(tasks: Sequence[Task], settings: RunSettings) -> Iterator[Outcome]:
    """The outcome of each task as it finishes. A task whose worker failed under it (KilledWorker after
    the scheduler's retries, a lost connection) is a failed outcome naming the exception."""
    with extra_needed("cluster", DASK_NEEDED_FOR):
        from dask.distributed import as_completed

    with dask_client(settings) as client:
        futures = client.map(run_task, list(tasks), pure=False)
        task_of = {future.key: task for future, task in zip(futures, tasks, strict=True)}
        for future in as_completed(futures):
            task = task_of[future.key]
            try:
                outcome = future.result()
            except Exception as exc:
                outcome = Outcome(task, None, f"worker failed: {type(exc).__name__}: {one_line(exc)}", 0.0)
            future.release()
            yield outcome


def _progress_line(number: int, total: int, outcome: Outcome) -> str:
    task = outcome.task
    said = f"ok in {outcome.seconds:.1f} s" if outcome.ok else f"failed: {outcome.reason}"
    return f"[{number}/{total}] {task.item.name} {task.analysis.value}: {said}"


def reanalyse(items: Sequence[Item], settings: RunSettings, say: Callable[[str], None]) -> RunReport:
    """Analyse the items not done before, store each result, write the summary; `say` gets one line per
    finished analysis (the progress) and one at the start."""
    out = settings.out
    out.mkdir(parents=True, exist_ok=True)
    done: dict[str, dict[Analysis, Done]] = {item.name: {} for item in items}
    digests: dict[str, str] = {}
    tasks: list[Task] = []
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
            before = stored(out, item, analysis, digests[item.name], settings.options)
            if before is not None:
                done[item.name][analysis] = before
            else:
                tasks.append(Task(item, analysis, settings.options))
    skipped = sum(d.document is not None for per_item in done.values() for d in per_item.values())
    where = settings.scheduler or f"a local cluster of {settings.workers} worker process(es)"
    say(
        f"{len(items)} recording(s): {len(tasks)} analysis(es) to run on {where}, "
        f"{skipped} done before (skipped)"
    )
    if tasks:
        for number, outcome in enumerate(run_on_dask(tasks, settings), start=1):
            item = outcome.task.item
            done[item.name][outcome.task.analysis] = save(out, outcome, digests[item.name])
            say(_progress_line(number, len(tasks), outcome))
    rows = [summary_row(item, {a: done[item.name][a] for a in settings.analyses}) for item in items]
    summary = write_summary(out, rows, Analysis.DIAGNOSE in settings.analyses)
    return RunReport(rows, summary, len(tasks), skipped)
