"""Tamper-evident results on SQLite and PostgreSQL: every succeeded job's result is chained to its lane's
previous one in the transaction that stores it; `verify_chain` and `shockbench verify` name the job whose
result was altered with a raw UPDATE, or whose link was deleted; concurrent successes in one lane still
make one unbroken chain."""

from __future__ import annotations

import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa

from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import JobKind
from service.store.result_chain import GENESIS, verify_chain


@pytest.fixture
def database(database_url: str) -> Iterator[Database]:
    database = Database(database_url)
    database.upgrade_schema()
    yield database
    database.dispose()


def succeed_job(store: JobStore, tmp: Path, gap_m: float) -> int:
    files = JobFiles(tmp / "r.csv", tmp / "v.toml", tmp)
    job = store.create(JobKind.IDENTIFY.value, {"points": 20}, lambda _i: files)
    assert store.mark_running(job.id)
    assert store.succeed(job.id, {"gap_m": gap_m, "curves": [{"corner": "ünö", "force_N": [1.5]}]}, {}, None)
    return job.id


def fill(database: Database, tmp: Path) -> dict[str, list[int]]:
    """Three results on lane north, two on south (interleaved), one failed job (not chained)."""
    north, south = JobStore(database, lane="north"), JobStore(database, lane="south")
    jobs: dict[str, list[int]] = {"north": [], "south": []}
    for i, (name, store) in enumerate([("north", north), ("south", south)] * 2 + [("north", north)]):
        jobs[name].append(succeed_job(store, tmp, 1e-5 * (i + 1)))
    failed = north.create(JobKind.IDENTIFY.value, {}, lambda _i: JobFiles(tmp, tmp, tmp))
    north.mark_running(failed.id)
    north.fail(failed.id, "diverged")
    return jobs


def shockbench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "service.cli.main", *args], capture_output=True, text=True, timeout=120
    )


def test_untouched_chains_verify(database: Database, database_url: str, tmp_path: Path) -> None:
    fill(database, tmp_path)
    with database.engine.connect() as c:
        links = c.execute(sa.text("SELECT lane, previous_hash, hash FROM result_chain ORDER BY id")).all()
    assert [link.lane for link in links] == ["north", "south", "north", "south", "north"]
    north = [link for link in links if link.lane == "north"]
    assert north[0].previous_hash == GENESIS
    assert [link.previous_hash for link in north[1:]] == [link.hash for link in north[:-1]]
    assert verify_chain(database).problem is None
    assert (verify_chain(database).results, verify_chain(database).lanes) == (5, 2)
    done = shockbench("verify", "--database", database_url)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "5 results in 2 lanes verified"
    one_lane = shockbench("verify", "--database", database_url, "--lane", "south")
    assert one_lane.stdout.strip() == "2 results in 1 lane verified"
    unknown = shockbench("verify", "--database", database_url, "--lane", "east")
    assert unknown.returncode == 2 and "lane 'east' has no stored results" in unknown.stderr


def test_an_altered_result_is_named(database: Database, database_url: str, tmp_path: Path) -> None:
    jobs = fill(database, tmp_path)
    altered = jobs["north"][1]
    with database.engine.begin() as c:  # someone edits the stored JSON behind the service's back
        c.execute(
            sa.text("UPDATE jobs SET result = :r WHERE id = :id"),
            {"r": '{"gap_m": 1e-09, "curves": [{"corner": "ünö", "force_N": [1.5]}]}', "id": altered},
        )
    report = verify_chain(database)
    assert report.problem is not None and f"job {altered}'s stored result was altered" in report.problem
    assert "lane 'north'" in report.problem
    done = shockbench("verify", "--database", database_url)
    assert done.returncode == 1
    assert done.stdout.strip() == report.problem and done.stdout.count("\n") == 1
    assert verify_chain(database, lane="south").problem is None  # the other lane's chain holds


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ("options = '{\"points\": 30}'", "'s stored result was altered"),
        ("lane = 'north'", "'s stored result was altered"),  # moved to another lane
        ("kind = 'diagnose'", "'s stored result was altered"),
        ("finished_at = created_at", "'s stored result was altered"),
        ("status = 'failed'", " succeeded but is now stored as failed"),
    ],
)
def test_every_hashed_column_and_the_status_are_guarded(
    database: Database, tmp_path: Path, change: str, named: str
) -> None:
    jobs = fill(database, tmp_path)
    altered = jobs["south"][0]
    with database.engine.begin() as c:
        c.execute(sa.text(f"UPDATE jobs SET {change} WHERE id = :id"), {"id": altered})
    report = verify_chain(database)
    assert report.problem is not None and f"job {altered}{named}" in report.problem
    assert report.problem.startswith("lane 'south'")


@pytest.mark.parametrize("which", [1, -1], ids=["middle", "newest"])
def test_a_deleted_link_is_named(database: Database, database_url: str, tmp_path: Path, which: int) -> None:
    jobs = fill(database, tmp_path)
    removed = jobs["north"][which]
    with database.engine.begin() as c:
        c.execute(sa.text("DELETE FROM result_chain WHERE job_id = :id"), {"id": removed})
    report = verify_chain(database)
    assert (
        report.problem == f"lane 'north': job {removed}'s result is not in the chain (its link was removed)"
    )
    done = shockbench("verify", "--database", database_url)
    assert done.returncode == 1 and done.stdout.strip() == report.problem


def test_concurrent_successes_in_one_lane_make_one_chain(database: Database, tmp_path: Path) -> None:
    """Two instances of one lane storing results at once: every append waits for the lane's previous one
    (PostgreSQL: the lane's advisory lock; without it two links would chain to the same previous hash and
    the unique constraint would refuse one)."""
    stores = [JobStore(database, lane="north"), JobStore(database, lane="north")]
    ready = [[s.create(JobKind.IDENTIFY.value, {}, lambda _i: JobFiles(tmp_path, tmp_path, tmp_path)).id
              for _ in range(15)] for s in stores]  # fmt: skip
    for store, ids in zip(stores, ready, strict=True):
        for job_id in ids:
            store.mark_running(job_id)
    start, failures = threading.Barrier(2), []

    def finish(store: JobStore, ids: list[int]) -> None:
        start.wait()
        for job_id in ids:
            try:
                assert store.succeed(job_id, {"gap_m": job_id * 1e-6}, {}, None)
            except Exception as exc:  # reported below
                failures.append(exc)

    threads = [threading.Thread(target=finish, args=pair) for pair in zip(stores, ready, strict=True)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert failures == []
    report = verify_chain(database)
    assert (report.problem, report.results, report.lanes) == (None, 30, 1)
