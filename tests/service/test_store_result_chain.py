"""Tamper-evident results on SQLite and PostgreSQL: every succeeded job's result is chained to its lane's
previous one in the transaction that stores it; `verify_chain` and `shockbench verify` name the job whose
result was altered with a raw UPDATE, or whose link was deleted, and which field changed when the result
was moved to another vehicle, sweep, recording, lane or thresholds version; concurrent successes in one
lane still make one unbroken chain."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import sqlalchemy as sa

from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import JobKind, JobRow, ResultChainRow, SweepRow, SweepStatus
from service.store.result_chain import GENESIS, covered_digests, verify_chain
from service.store.sweeps import SweepStore


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


THRESHOLDS = "shockbench-default-2026.1"
MOVED = "sweep_recording_sha256, sweep_uid, vehicle_id"
"""What pointing a result at another sweep (of another car) changes."""


def swept_vehicle(database: Database, tmp: Path, lane: str, vehicle_id: str, recording: bytes) -> int:
    """A sweep of `vehicle_id` on `lane` whose recording file holds `recording`, ended; its id."""
    sweeps = SweepStore(database, lane=lane)
    sweep = sweeps.create("bench", {"vehicle_id": vehicle_id}, lambda i: (tmp / f"{i}.h5", tmp / f"{i}.toml"))
    assert sweep.recording_path is not None
    Path(sweep.recording_path).write_bytes(recording)
    assert sweeps.mark_running(sweep.id)
    assert sweeps.finish(sweep.id, SweepStatus.COMPLETE, complete=True, reason=None)
    return sweep.id


def judged_on_sweep(database: Database, tmp: Path, lane: str, sweep_id: int, gap_m: float) -> int:
    """A succeeded identification of the sweep's recording whose result carries a verdict; its id."""
    store = JobStore(database, lane=lane)
    sweep = SweepStore(database).get(sweep_id)
    assert sweep is not None and sweep.recording_path is not None
    files = JobFiles(Path(sweep.recording_path), tmp / "v.toml", tmp)
    job = store.create(JobKind.IDENTIFY.value, {}, lambda _i: files, input_source="sweep", sweep_id=sweep_id)
    assert store.mark_running(job.id)
    verdict = {"verdict": "pass", "thresholds_version": THRESHOLDS, "reasons": []}
    assert store.succeed(job.id, {"gap_m": gap_m, "verdict": verdict}, {}, None)
    return job.id


def test_the_recordings_are_hashed_when_the_sweep_ends_and_the_job_is_submitted(
    database: Database, tmp_path: Path
) -> None:
    sweep = swept_vehicle(database, tmp_path, "north", "AB-12", b"recording bytes \x00\xff")
    job = judged_on_sweep(database, tmp_path, "north", sweep, 1e-5)
    with database.engine.connect() as c:
        swept = c.execute(
            sa.text("SELECT recording_sha256 FROM sweeps WHERE id = :id"), {"id": sweep}
        ).scalar()
        ran = c.execute(sa.text("SELECT recording_sha256 FROM jobs WHERE id = :id"), {"id": job}).scalar()
        link = c.execute(
            sa.text("SELECT link_version, sequence FROM result_chain WHERE job_id = :id"), {"id": job}
        )
        assert tuple(link.one()) == (2, 1)
    assert swept == ran == hashlib.sha256(b"recording bytes \x00\xff").hexdigest()
    assert verify_chain(database).problem is None


@pytest.mark.parametrize(
    ("change", "fields"),
    [
        ("UPDATE sweeps SET settings = '{\"vehicle_id\": \"XY-99\"}' WHERE id = :sweep", "vehicle_id"),
        ("UPDATE jobs SET sweep_id = :other WHERE id = :job", MOVED),
        ("UPDATE sweeps SET uid = 'another-sweep' WHERE id = :sweep", "sweep_uid"),
        ("UPDATE sweeps SET recording_sha256 = :fake WHERE id = :sweep", "sweep_recording_sha256"),
        ("UPDATE jobs SET recording_sha256 = :fake WHERE id = :job", "recording_sha256"),
        ("UPDATE jobs SET recording_sha256 = NULL WHERE id = :job", "recording_sha256"),
        ("UPDATE jobs SET lane = 'north' WHERE id = :job", "lane"),
        ("UPDATE jobs SET result = :ten_percent_more WHERE id = :job", "result"),
        ("UPDATE jobs SET result = :other_thresholds WHERE id = :job", "result, thresholds_version"),
    ],
    ids=["vehicle", "sweep", "sweep uid", "sweep recording", "recording", "no recording", "lane", "result",
         "thresholds"],
)  # fmt: skip
def test_a_result_moved_to_another_vehicle_sweep_recording_lane_or_thresholds_is_named(
    database: Database, database_url: str, tmp_path: Path, change: str, fields: str
) -> None:
    """A passing result is tied to what it is about: the database edited behind the service's back, verify
    names the job, its lane and what no longer matches."""
    other = swept_vehicle(database, tmp_path, "north", "XY-99", b"another car")
    judged_on_sweep(database, tmp_path, "north", other, 3e-5)
    sweep = swept_vehicle(database, tmp_path, "south", "AB-12", b"the car")
    job = judged_on_sweep(database, tmp_path, "south", sweep, 1e-5)
    judged_on_sweep(database, tmp_path, "south", sweep, 2e-5)  # a later link, which still follows
    verdict = {"verdict": "pass", "thresholds_version": THRESHOLDS, "reasons": []}
    values = {
        "sweep": sweep,
        "job": job,
        "other": other,
        "fake": "f" * 64,
        "ten_percent_more": json.dumps({"gap_m": 1.1e-5, "verdict": verdict}),
        "other_thresholds": json.dumps({"gap_m": 1e-5, "verdict": {**verdict, "thresholds_version": "lax"}}),
    }
    assert verify_chain(database).problem is None
    with database.engine.begin() as c:
        c.execute(sa.text(change), {k: v for k, v in values.items() if f":{k}" in change})
        link = c.execute(sa.text("SELECT id FROM result_chain WHERE job_id = :id"), {"id": job}).scalar()
    matches = "matches" if ", " not in fields else "match"
    expected = (
        f"lane 'south': job {job}'s stored result was altered: its {fields} no longer {matches} its hash "
    )
    assert verify_chain(database).problem == f"{expected}(chain link {link})"
    done = shockbench("verify", "--database", database_url)
    assert done.returncode == 1 and done.stdout.strip() == f"{expected}(chain link {link})"


def test_a_link_whose_recorded_fields_were_edited_is_named(database: Database, tmp_path: Path) -> None:
    sweep = swept_vehicle(database, tmp_path, "north", "AB-12", b"the car")
    job = judged_on_sweep(database, tmp_path, "north", sweep, 1e-5)
    with database.sessions.begin() as session:  # the vehicle moved, and the link's digest with it
        session.execute(sa.update(SweepRow).values(settings={"vehicle_id": "XY-99"}))
        link = session.scalars(sa.select(ResultChainRow)).one()
        now = session.get(JobRow, job)
        assert now is not None
        link.covered = covered_digests(now, session.get(SweepRow, sweep))
    assert verify_chain(database).problem == (
        f"lane 'north': chain link {link.id} (job {job}) was altered: its hash no longer matches the fields "
        "it records"
    )
