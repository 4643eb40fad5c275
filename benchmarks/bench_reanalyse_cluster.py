"""Benchmark (issue 33): an archive in the database and its re-analysis on Dask, side by side in one run.

    .venv/bin/python benchmarks/bench_reanalyse_cluster.py
    .venv/bin/python benchmarks/bench_reanalyse_cluster.py --recordings 100 --distinct 10 --seconds 12 \\
        --workdir /tmp/reanalyse-cluster-bench --repeats 3 --max-others-cpu 0.5

The archive: `--distinct` quarter-car sweeps of `--seconds` s at 1 kHz (simulators.vehicle_sim, default
car, seeds 0..distinct-1), each copied until there are `--recordings` CSV files, every copy with bytes of
its own (a comment line names the copy: the database stores each once by its sha256), one vehicle.toml.

Measured (no OPENBLAS_NUM_THREADS set here: the workers set their own): first the import, then `--repeats`
rounds of the others side by side (the machine's speed drifts from minute to minute even when nothing else
runs on it), medians reported:
1. import: `shockbench archive import`'s code into a fresh SQLite file: recordings per second, bytes per
   recording as files and as stored;
2. in-process: service.reanalyse.task.run_task on each recording (after one warm-up; glibc's allocator
   set up as `shockbench identify` and the workers set it up), its mean wall time: the reference cost of
   one identification here;
3. workers1 and workers2: service.reanalyse.run.reanalyse on the database (a LocalCluster of 1 and 2
   worker processes, recordings shipped as bytes in batches), each run in a fresh Python process with only
   what `shockbench reanalyse` has loaded when it starts its cluster (Dask's import is part of the start),
   wall time from the call to its return, the cluster's start and stop included, and the mean time a
   worker spent per recording (Outcome.seconds: the analysis, reading included) against the in-process
   cost.
The per-recording breakdown divides each run's wall time into the cluster's start (until its client is up,
workers set up), worker compute (worker time over the workers), and the rest (shipping the bytes,
scheduling, storing results, the last batch's tail, the cluster's stop).

The machine may be shared: every measurement prints the CPU that other processes took meanwhile (the
machine's busy time in /proc/stat less this process's and its workers'). With --max-others-cpu S, a cluster
run during which they took more than S CPU seconds is discarded and run again (at most --attempts runs,
the last one kept whatever it saw); the discarded runs are printed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
if TYPE_CHECKING:
    from service.reanalyse.sources import Item


def busy_cpu_s() -> float | None:
    """CPU seconds the whole machine has spent busy since boot (Linux's /proc/stat), None elsewhere."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]
    except OSError:
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = (int(v) for v in fields[:8])
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def own_cpu_s() -> float:
    """CPU seconds of this process and of the child processes it has reaped (the cluster's workers)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def others_cpu_s(machine_before: float | None, own_before: float) -> float | None:
    """CPU seconds other processes took since the two readings (the machine's busy time less ours)."""
    machine = busy_cpu_s()
    if machine is None or machine_before is None:
        return None
    return max(0.0, machine - machine_before - (own_cpu_s() - own_before))


@dataclass(frozen=True)
class ClusterRun:
    """One re-analysis on a local cluster: wall time from the call to its return, until its client was up
    (workers started and set up), the mean worker time a recording, recordings, from the last result to
    the return (the cluster's stop), and the CPU other processes took meanwhile (None: not known)."""

    wall_s: float
    start_s: float
    worker_s: float
    recordings: int
    stop_s: float
    others_cpu_s: float | None


def timed_run(url: str, workers: int) -> ClusterRun:
    """One re-analysis of the whole database on a local cluster of `workers` processes, in a fresh Python
    process (run_alone) that has loaded only what `shockbench reanalyse` has when it starts its cluster
    (Dask itself is imported as part of the start, as in the command). Other processes' CPU is read here,
    around it."""
    machine, own = busy_cpu_s(), own_cpu_s()
    child = subprocess.run(
        [sys.executable, __file__, "--run-alone", url, str(workers)],
        capture_output=True,
        text=True,
    )
    if child.returncode != 0:
        raise SystemExit(f"the re-analysis failed:\n{child.stderr}")
    others = others_cpu_s(machine, own)
    *lines, result = child.stdout.splitlines()
    print(*lines, sep="\n", flush=True)
    return ClusterRun(**json.loads(result), others_cpu_s=others)


def run_alone(url: str, workers: int) -> None:
    """timed_run's process: the re-analysis, its client's CPU a recording printed, then its ClusterRun (but
    for others_cpu_s) as one JSON line."""
    from service.reanalyse import run
    from service.reanalyse.sources import items_in_database, open_archive

    database = open_archive(url)
    up: list[float] = []
    last: list[float] = []
    seconds: list[float] = []

    def progress(number: int, total: int, outcome: object) -> None:
        last[:] = [time.perf_counter()]
        assert outcome.ok, outcome.reason  # type: ignore[attr-defined]
        seconds.append(outcome.seconds)  # type: ignore[attr-defined]

    try:
        items = items_in_database(database)
        start = time.perf_counter()
        settings = run.RunSettings(out=None, workers=workers, database=database)
        cpu = time.process_time()
        client_up = lambda client: up.append(time.perf_counter())  # noqa: E731
        run.reanalyse(items, settings, lambda _l: None, progress, client_up)
        wall = time.perf_counter() - start
        client_cpu = time.process_time() - cpu  # this process: the client and the local scheduler
    finally:
        database.dispose()
        # the workers are forked from the forkserver (service.reanalyse.forkserver), whose CPU and theirs
        # reach this process's reaped children only once it is stopped and waited for; it would otherwise
        # end after this process and count as other processes' CPU (multiprocessing's own stop, private)
        from multiprocessing import forkserver

        forkserver._forkserver._stop()
    print(f"    client and scheduler CPU {client_cpu / len(seconds) * 1e3:.1f} ms a recording", flush=True)
    stop = start + wall - last[0]
    fields = asdict(ClusterRun(wall, up[0] - start, statistics.mean(seconds), len(seconds), stop, None))
    del fields["others_cpu_s"]
    print(json.dumps(fields), flush=True)


def in_process_loop(items: list[Item]) -> float:
    """Mean wall seconds of run_task (the in-process reference) over the items, printed with the CPU other
    processes took meanwhile."""
    from service.reanalyse.task import Analysis, AnalysisOptions, Task, run_task

    machine, own = busy_cpu_s(), own_cpu_s()
    start = time.perf_counter()
    for item in items:
        outcome = run_task(Task(item, Analysis.IDENTIFY, AnalysisOptions()))
        assert outcome.ok, outcome.reason
    mean = (time.perf_counter() - start) / len(items)
    others = others_cpu_s(machine, own)
    print(
        f"  in-process: {mean * 1e3:.0f} ms a recording ({len(items)} recordings), load "
        f"{os.getloadavg()[0]:.1f}, other processes' CPU {'?' if others is None else f'{others:.1f} s'}",
        flush=True,
    )
    return mean


def measured(url: str, workers: int, max_others_cpu_s: float | None, attempts: int) -> ClusterRun:
    """timed_run, run again (up to `attempts` in all) while other processes took more than
    max_others_cpu_s of CPU during it (None: never); each run printed, a discarded one said so."""
    for attempt in range(1, attempts + 1):
        run = timed_run(url, workers)
        others = "?" if run.others_cpu_s is None else f"{run.others_cpu_s:.1f} s"
        disturbed = (
            max_others_cpu_s is not None
            and run.others_cpu_s is not None
            and run.others_cpu_s > max_others_cpu_s
        )
        print(
            f"  workers{workers}: {run.wall_s:.2f} s wall ({run.start_s:.2f} s cluster start), worker "
            f"{run.worker_s * 1e3:.0f} ms a recording, stop {run.stop_s:.2f} s, load "
            f"{os.getloadavg()[0]:.1f}, other processes' CPU {others}"
            + (" (disturbed: discarded, run again)" if disturbed and attempt < attempts else ""),
            flush=True,
        )
        if not disturbed:
            break
    return run


def main() -> None:
    if sys.argv[1:2] == ["--run-alone"]:
        url, workers = sys.argv[2:4]
        run_alone(url, int(workers))
        return
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--recordings", type=int, default=100)
    parser.add_argument("--distinct", type=int, default=10)
    parser.add_argument("--seconds", type=float, default=12.0)
    parser.add_argument("--repeats", type=int, default=1, help="rounds of the cluster runs (median)")
    parser.add_argument(
        "--max-others-cpu",
        type=float,
        default=None,
        help="a cluster run during which other processes took more CPU seconds than this is run again "
        "(the machine is shared; default: every run counts)",
    )
    parser.add_argument("--attempts", type=int, default=4, help="runs at most per measurement")
    parser.add_argument(
        "--workdir", type=Path, default=Path(tempfile.gettempdir()) / "shockbench-reanalyse-cluster-bench"
    )
    args = parser.parse_args()

    from bench_reanalyse import make_archive  # the archive bench_reanalyse.py makes, unique copies

    from service.allocator import keep_freed_memory
    from service.reanalyse.archive import import_folder
    from service.reanalyse.sources import items_in_folder
    from service.reanalyse.task import Analysis, AnalysisOptions, Task, run_task, warm_up
    from service.store.database import Database

    archive = args.workdir / "archive"
    make_archive(archive, args.recordings, args.distinct, args.seconds, unique_copies=True)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}; "
        f"{args.recordings} recordings of {args.seconds:g} s ({args.distinct} simulated); "
        f"load {os.getloadavg()[0]:.1f}",
        flush=True,
    )

    db_file = args.workdir / "archive.sqlite3"
    db_file.unlink(missing_ok=True)
    url = f"sqlite:///{db_file}"
    database = Database(url)
    database.upgrade_schema()
    report = import_folder(archive, database, print)
    database.dispose()
    assert not report.failed and report.stored == args.recordings, report
    print(
        f"import: {report.stored / report.seconds:.1f} recordings/s; per recording "
        f"{report.bytes_in / report.stored / 1e3:.0f} kB as a file, "
        f"{report.bytes_stored / report.stored / 1e3:.0f} kB stored "
        f"({report.bytes_stored / report.bytes_in:.0%})",
        flush=True,
    )

    warm_up()  # as a worker does: one BLAS thread, the estimator loaded
    keep_freed_memory()  # glibc's allocator as `shockbench identify` and the workers set it up
    items = [item for item in items_in_folder(archive) if item.recording.suffix == ".csv"]
    run_task(Task(items[0], Analysis.IDENTIFY, AnalysisOptions()))
    loops: list[float] = []
    runs: dict[int, list[ClusterRun]] = {1: [], 2: []}
    for _ in range(args.repeats):  # side by side: the machine's speed drifts even when nothing else runs
        loops.append(in_process_loop(items))
        for workers in (1, 2):
            shutil.rmtree(args.workdir / "dask-worker-space", ignore_errors=True)
            runs[workers].append(measured(url, workers, args.max_others_cpu, args.attempts))
    in_process = statistics.median(loops)
    print("| mode | wall (median) | cluster start | worker per recording | against in-process |")
    print("|---|---:|---:|---:|---:|")
    print(f"| in-process loop | {in_process * len(items):.2f} s | - | {in_process * 1e3:.0f} ms | 1.00× |")
    walls = {}
    for workers in (1, 2):
        done = runs[workers]
        wall = walls[workers] = statistics.median(r.wall_s for r in done)
        to_first = statistics.median(r.start_s for r in done)
        per = statistics.median(r.worker_s for r in done)
        print(
            f"| {workers} worker(s) | {wall:.2f} s | {to_first:.2f} s | {per * 1e3:.0f} ms | "
            f"{per / in_process:.2f}× |"
        )
        n = done[0].recordings
        stop = statistics.median(r.stop_s for r in done)
        rest = wall - to_first - stop - per * n / workers
        print(
            f"  wall per recording, {workers} worker(s): {wall / n * 1e3:.0f} ms = cluster start "
            f"{to_first / n * 1e3:.0f} + compute {per / workers * 1e3:.0f} (worker time / workers) + "
            f"cluster stop {stop / n * 1e3:.0f} + shipping, scheduling, storing, uneven end "
            f"{rest / n * 1e3:.0f}"
        )
    print(f"2 workers against 1: {walls[1] / walls[2]:.2f}×; 2 workers total {walls[2]:.2f} s")


if __name__ == "__main__":
    main()
