"""Benchmark: how fast a lane's sync backlog drains once the central database is back (service.store.sync),
and what the outbox adds to storing a result in the local store.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_sync_backlog.py [--jobs 1000]

A local store (SQLite in a temporary folder, with the outbox) fills as a lane cut off from its central
database would: `--jobs` identification jobs succeed with the same real result (about 3 kB of JSON, with its
chain link), every tenth on a finished sweep of its own; the time of each `succeed` is taken. The same is
done on a store without the outbox (interleaved runs) for the outbox's cost. Then a PostgreSQL server
started as the tests start it (tests/pg_server.py, fsync off) takes the whole backlog through
`CentralSync.push_pending` (one central transaction per entry), timed, and `verify_chain` checks the
central chain.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from bench_result_chain import real_result

from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import JobKind, SweepStatus
from service.store.outbox import backlog
from service.store.result_chain import verify_chain
from service.store.sweeps import SweepStore
from service.store.sync import CentralSync

LANE = "bench-lane"


def fill(database: Database, jobs: int, result: dict[str, Any], folder: Path) -> list[float]:
    """`jobs` succeeded jobs (every tenth on a sweep); the seconds each `succeed` took."""
    store, sweeps = JobStore(database, lane=LANE), SweepStore(database, lane=LANE)
    files = JobFiles(folder / "r.csv", folder / "v.toml", folder)
    taken = []
    for i in range(jobs):
        sweep_id = None
        if i % 10 == 0:
            sweep = sweeps.create(
                "bench", {"vehicle_id": f"V{i}"}, lambda s: (folder / f"{s}.h5", folder / "v")
            )
            sweeps.mark_running(sweep.id)
            sweeps.finish(sweep.id, SweepStatus.COMPLETE, complete=True, reason=None)
            sweep_id = sweep.id
        job = store.create(JobKind.IDENTIFY.value, {"points": 20}, lambda _i: files, sweep_id=sweep_id)
        store.mark_running(job.id, owner=LANE)
        start = time.perf_counter()
        assert store.succeed(job.id, result, {}, None, owner=LANE)
        taken.append(time.perf_counter() - start)
    return taken


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=1000)
    args = parser.parse_args()
    result = real_result()
    from pg_server import PostgresServer, find_bindir

    bindir = find_bindir()
    assert bindir is not None, "no PostgreSQL binaries"
    with tempfile.TemporaryDirectory() as folder, PostgresServer(bindir) as server:
        local = Database(f"sqlite:///{folder}/local.sqlite3", outbox=True)
        plain = Database(f"sqlite:///{folder}/plain.sqlite3")
        for database in (local, plain):
            database.upgrade_schema()
        with_outbox: list[float] = []
        without: list[float] = []
        for _ in range(10):  # interleaved, so that the machine's load weighs on both alike
            with_outbox += fill(local, args.jobs // 10, result, Path(folder))
            without += fill(plain, args.jobs // 10, result, Path(folder))
        waiting = backlog(local).count
        central = Database(server.new_database())
        central.upgrade_schema()
        start = time.perf_counter()
        pushed = CentralSync(local, central).push_pending()
        drain_s = time.perf_counter() - start
        report = verify_chain(central)
        assert report.problem is None and report.results == len(with_outbox), report
        assert len(pushed) == waiting and backlog(local).count == 0
        print(
            f"succeed in the local store: {statistics.median(with_outbox) * 1e3:.2f} ms with the outbox, "
            f"{statistics.median(without) * 1e3:.2f} ms without (median of {len(without)} each)"
        )
        print(
            f"backlog of {waiting} entries ({len(with_outbox)} jobs, {waiting - len(with_outbox)} sweeps) "
            f"pushed to PostgreSQL in {drain_s:.2f} s: {drain_s / waiting * 1e3:.2f} ms per entry, "
            f"{waiting / drain_s:.0f} entries/s; central chain of {report.results} results verified"
        )
        for database in (local, plain, central):
            database.dispose()


if __name__ == "__main__":
    main()
