"""Benchmark (issue 33): an archive in the database and its re-analysis on Dask, side by side in one run.

    .venv/bin/python benchmarks/bench_reanalyse_cluster.py
    .venv/bin/python benchmarks/bench_reanalyse_cluster.py --recordings 100 --distinct 10 --seconds 12 \\
        --workdir /tmp/reanalyse-cluster-bench --repeats 3

The archive: `--distinct` quarter-car sweeps of `--seconds` s at 1 kHz (simulators.vehicle_sim, default
car, seeds 0..distinct-1), each copied until there are `--recordings` CSV files, every copy with bytes of
its own (a comment line names the copy: the database stores each once by its sha256), one vehicle.toml.

Measured, in this order, in this process (no OPENBLAS_NUM_THREADS set here: the workers set their own):
1. import: `shockbench archive import`'s code into a fresh SQLite file: recordings per second, bytes per
   recording as files and as stored;
2. in-process: service.reanalyse.task.run_task on each recording (after one warm-up), its mean wall time:
   the reference cost of one identification here;
3. workers1 and workers2: service.reanalyse.run.reanalyse on the database (a LocalCluster of 1 and 2
   worker processes, recordings shipped as bytes in batches), wall time from the call to its return, the
   cluster's start and stop included, and the mean time a worker spent per recording (Outcome.seconds:
   the analysis, reading included) against the in-process cost.
The per-recording breakdown divides each run's wall time into the cluster's start (until its client is up,
workers set up), worker compute (worker time over the workers), and the rest (shipping the bytes,
scheduling, storing results, the last batch's tail, the cluster's stop).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_reanalyse import make_archive  # noqa: E402  (the archive bench_reanalyse.py makes, unique copies)


def timed_run(url: str, workers: int) -> tuple[float, float, float, int, float]:
    """(wall s, s until the cluster's client is up (its workers started and set up), mean worker s per
    recording, recordings, s from the last result to the return: the cluster's stop) of one re-analysis."""
    from service.reanalyse.run import RunSettings, reanalyse
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
        settings = RunSettings(out=None, workers=workers, database=database)
        cpu = time.process_time()
        client_up = lambda client: up.append(time.perf_counter())  # noqa: E731
        reanalyse(items, settings, lambda _l: None, progress, client_up)
        wall = time.perf_counter() - start
        client_cpu = time.process_time() - cpu  # this process: the client and the local scheduler
    finally:
        database.dispose()
    print(f"    client and scheduler CPU {client_cpu / len(seconds) * 1e3:.1f} ms a recording", flush=True)
    return wall, up[0] - start, statistics.mean(seconds), len(seconds), start + wall - last[0]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--recordings", type=int, default=100)
    parser.add_argument("--distinct", type=int, default=10)
    parser.add_argument("--seconds", type=float, default=12.0)
    parser.add_argument("--repeats", type=int, default=1, help="rounds of the cluster runs (median)")
    parser.add_argument(
        "--workdir", type=Path, default=Path(tempfile.gettempdir()) / "shockbench-reanalyse-cluster-bench"
    )
    args = parser.parse_args()

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
    items = [item for item in items_in_folder(archive) if item.recording.suffix == ".csv"]
    run_task(Task(items[0], Analysis.IDENTIFY, AnalysisOptions()))
    start = time.perf_counter()
    for item in items:
        outcome = run_task(Task(item, Analysis.IDENTIFY, AnalysisOptions()))
        assert outcome.ok, outcome.reason
    in_process = (time.perf_counter() - start) / len(items)
    print(f"in-process: {in_process * 1e3:.0f} ms a recording ({len(items)} recordings)", flush=True)

    runs: dict[int, list[tuple[float, float, float, int, float]]] = {1: [], 2: []}
    for _ in range(args.repeats):
        for workers in (1, 2):
            shutil.rmtree(args.workdir / "dask-worker-space", ignore_errors=True)
            runs[workers].append(timed_run(url, workers))
            wall, to_first, per, n, stop = runs[workers][-1]
            print(
                f"  workers{workers}: {wall:.2f} s wall ({to_first:.2f} s cluster start), worker "
                f"{per * 1e3:.0f} ms a recording, stop {stop:.2f} s, load {os.getloadavg()[0]:.1f}",
                flush=True,
            )
    print("| mode | wall (median) | cluster start | worker per recording | against in-process |")
    print("|---|---:|---:|---:|---:|")
    print(f"| in-process loop | {in_process * len(items):.2f} s | - | {in_process * 1e3:.0f} ms | 1.00× |")
    walls = {}
    for workers in (1, 2):
        wall = walls[workers] = statistics.median(r[0] for r in runs[workers])
        to_first = statistics.median(r[1] for r in runs[workers])
        per = statistics.median(r[2] for r in runs[workers])
        print(
            f"| {workers} worker(s) | {wall:.2f} s | {to_first:.2f} s | {per * 1e3:.0f} ms | "
            f"{per / in_process:.2f}× |"
        )
        n = runs[workers][0][3]
        stop = statistics.median(r[4] for r in runs[workers])
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
