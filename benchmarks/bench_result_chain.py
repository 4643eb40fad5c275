"""Benchmark: what the result chain costs (service.store.result_chain): storing a result with its link
against the same UPDATE without it, and `verify` over every stored result.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_result_chain.py [--results 1000] [--postgres]

Each job stores the same real identification result (quarter car, 20 points, intervals: the JSON the worker
stores, about 3 kB). Half the jobs succeed with their link (JobStore.succeed), half with the bare UPDATE
(the transition without the append), interleaved; then verify_chain walks the chained half. SQLite in a
temporary folder; with --postgres also a PostgreSQL server started as the tests start it
(tests/pg_server.py, fsync off).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from sqlalchemy import text

from estimator.identify import IdentifyOptions, identify
from service.jobs.context import finite_json
from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import JobKind, JobStatus, utcnow
from service.store.result_chain import verify_chain
from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate


def real_result() -> dict[str, Any]:
    car = default_quarter_car()
    recording = simulate(car, SimulationSettings(seed=1)).recording
    return finite_json(identify(recording, car.known, IdentifyOptions()).to_json())


def run(url: str, results: int, result: dict[str, Any], folder: Path) -> None:
    database = Database(url)
    database.upgrade_schema()
    store = JobStore(database, lane="bench-lane")
    files = JobFiles(folder / "r.csv", folder / "v.toml", folder)
    chained: list[float] = []
    bare: list[float] = []
    for i in range(results):
        job = store.create(JobKind.IDENTIFY.value, {"points": 20}, lambda _i: files)
        store.mark_running(job.id)
        start = time.perf_counter()
        if i % 2 == 0:
            assert store.succeed(job.id, result, {}, None)
            chained.append(time.perf_counter() - start)
        else:
            values = {"status": JobStatus.SUCCEEDED.value, "result": result, "finished_at": utcnow()}
            assert store._transition(job.id, (JobStatus.RUNNING,), **values)  # the UPDATE alone
            bare.append(time.perf_counter() - start)
    start = time.perf_counter()
    with database.engine.begin() as c:  # the unchained half would be reported: take it out of the lane
        c.execute(text("UPDATE jobs SET lane = 'bare' WHERE id % 2 = 0"))
    report = verify_chain(database, lane="bench-lane")
    verify_s = time.perf_counter() - start
    assert report.problem is None, report.problem
    database.dispose()
    name = url.split(":", 1)[0]
    print(
        f"{name}: store a result: {statistics.median(chained) * 1e3:.2f} ms with its link, "
        f"{statistics.median(bare) * 1e3:.2f} ms without (median of {len(chained)} each); "
        f"verify {report.results} results: {verify_s:.2f} s ({verify_s / report.results * 1e3:.2f} ms each)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=int, default=1000)
    parser.add_argument("--postgres", action="store_true")
    args = parser.parse_args()
    result = real_result()
    print(f"result JSON: {len(json.dumps(result))} bytes")
    with tempfile.TemporaryDirectory() as folder:
        run(f"sqlite:///{folder}/bench.sqlite3", args.results, result, Path(folder))
        if args.postgres:
            from pg_server import PostgresServer, find_bindir

            bindir = find_bindir()
            assert bindir is not None, "no PostgreSQL binaries"
            with PostgresServer(bindir) as server:
                run(server.new_database(), args.results, result, Path(folder))


if __name__ == "__main__":
    main()
