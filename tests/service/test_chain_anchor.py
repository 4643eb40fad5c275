"""The result chain's head anchored outside the chain, on SQLite and PostgreSQL: a lane logs every new head
in its heads log and checkpoints it on the central database when it syncs; deleting the newest results (or
rewriting the chain with every hash recomputed) passes the chain alone but fails `verify` against the log
and against the central checkpoints, naming the missing links."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
import sqlalchemy as sa

from service.store.chain_anchor import HEADS_FILE, Head, HeadLog
from service.store.database import Database, default_database_url
from service.store.jobs import JobFiles, JobStore
from service.store.models import ChainCheckpointRow, JobRow, ResultChainRow, SweepRow, SweepStatus
from service.store.result_chain import GENESIS, covered_digests, link_hash_v2, verify_chain
from service.store.sweeps import SweepStore
from service.store.sync import CentralSync

LANE = "north"


def clock() -> Iterator[datetime]:
    start = datetime(2026, 11, 25, 8, 0, tzinfo=UTC)
    return (start + timedelta(minutes=n) for n in range(10_000))


def heads_log(folder: Path) -> HeadLog:
    ticks = clock()
    return HeadLog(folder / HEADS_FILE, clock=lambda: next(ticks))


def results(database: Database, tmp: Path, heads: HeadLog | None, count: int) -> list[int]:
    """`count` identifications of one vehicle's sweep on the lane, stored with `heads` as the heads log."""
    sweeps = SweepStore(database, lane=LANE)
    sweep = sweeps.create("bench", {"vehicle_id": "AB-12"}, lambda i: (tmp / f"{i}.h5", tmp / f"{i}.toml"))
    assert sweep.recording_path is not None
    Path(sweep.recording_path).write_bytes(b"recording")
    assert sweeps.mark_running(sweep.id)
    assert sweeps.finish(sweep.id, SweepStatus.COMPLETE, complete=True, reason=None)
    store = JobStore(database, lane=LANE, heads=heads)
    files = JobFiles(Path(sweep.recording_path), tmp / "v.toml", tmp)
    ids = []
    for n in range(count):
        job = store.create("identify", {}, lambda _i: files, input_source="sweep", sweep_id=sweep.id)
        assert store.mark_running(job.id, owner=LANE)
        assert store.succeed(job.id, {"gap_m": 1e-5 * (n + 1)}, {}, None, owner=LANE)
        ids.append(job.id)
    return ids


def delete_results(database: Database, job_ids: list[int]) -> None:
    """What someone with write access to the database does to make results disappear: the jobs and their
    links, leaving a shorter chain that holds."""
    with database.engine.begin() as c:
        for job_id in job_ids:
            c.execute(sa.text("DELETE FROM result_chain WHERE job_id = :id"), {"id": job_id})
            c.execute(sa.text("DELETE FROM jobs WHERE id = :id"), {"id": job_id})


def shockbench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "service.cli.main", *args], capture_output=True, text=True, timeout=120
    )


def test_every_new_head_is_logged_once_after_its_result_is_stored(database: Database, tmp_path: Path) -> None:
    log = heads_log(tmp_path)
    ids = results(database, tmp_path, log, 3)
    with database.engine.connect() as c:
        links = c.execute(sa.text("SELECT sequence, job_id, hash FROM result_chain ORDER BY id")).all()
    lines = [json.loads(line) for line in (tmp_path / HEADS_FILE).read_text().splitlines()]
    assert lines == [
        {
            "lane": LANE,
            "sequence": n,
            "job_id": job,
            "hash": link.hash,
            "at": f"2026-11-25T08:0{n - 1}:00+00:00",
        }
        for n, job, link in zip((1, 2, 3), ids, links, strict=True)
    ]
    assert [(link.sequence, link.job_id) for link in links] == [(1, ids[0]), (2, ids[1]), (3, ids[2])]
    checkpoints, unreadable = log.checkpoints()
    report = verify_chain(database, checkpoints=checkpoints)
    assert (report.problem, report.results, report.checkpoints, unreadable) == (None, 3, 3, 0)


@pytest.mark.parametrize("removed", [1, 2, 4])
def test_deleting_the_newest_results_fails_against_the_heads_log(
    database: Database, tmp_path: Path, removed: int
) -> None:
    """Removing the newest result, the two newest, or all of them (the lane then has no chain left: it is
    known from the log alone)."""
    log = heads_log(tmp_path)
    ids = results(database, tmp_path, log, 4)
    delete_results(database, ids[-removed:])
    assert verify_chain(database).problem is None  # the shorter chain holds by itself

    report = verify_chain(database, checkpoints=log.checkpoints()[0])

    kept = 4 - removed
    ends = f"the chain ends at link {kept}" if kept else "no link of the chain is left"
    links = "link 4 (job" if removed == 1 else f"links {kept + 1}-4 (jobs"
    assert report.problem == (
        f"lane 'north': {ends}, but heads log {log.path} line 4 checkpointed link 4 (job {ids[3]}) at "
        f"2026-11-25T08:03:00+00:00: {links} {', '.join(map(str, ids[kept:]))}) "
        f"{'is' if removed == 1 else 'are'} missing (the newest results were removed)"
    )
    assert verify_chain(database, lane="north", checkpoints=log.checkpoints()[0]).problem == report.problem


def test_shockbench_verify_reads_the_data_directorys_heads_log(tmp_path: Path) -> None:
    data = tmp_path / "data"
    database = Database(default_database_url(data))
    try:
        database.upgrade_schema()
        ids = results(database, tmp_path, HeadLog.in_data_dir(data), 3)
        intact = shockbench("verify", "--data", str(data))
        assert intact.returncode == 0, intact.stderr
        assert intact.stdout.strip() == "3 results in 1 lane verified, their heads against 3 checkpoints"
        delete_results(database, ids[-1:])
    finally:
        database.dispose()
    done = shockbench("verify", "--data", str(data))
    assert done.returncode == 1
    assert done.stdout.startswith(
        f"lane 'north': the chain ends at link 2, but heads log {data / HEADS_FILE}"
    )
    assert f"link 3 (job {ids[2]}) is missing" in done.stdout
    url = default_database_url(data)
    assert shockbench("verify", "--database", url).returncode == 0  # another database: not its log ...
    named = shockbench("verify", "--database", url, "--heads", str(data / HEADS_FILE))  # ... unless named
    assert named.returncode == 1 and named.stdout == done.stdout
    absent = shockbench("verify", "--database", url, "--heads", str(tmp_path / "none.jsonl"))
    assert absent.returncode == 2 and "heads log" in absent.stderr and "does not exist" in absent.stderr


def rewrite_chain(database: Database, lane: str) -> None:
    """Recompute every link of the lane from the stored rows as they are now, as a forger with the recipe
    (the module docstring) and write access to the whole chain would."""
    with database.sessions.begin() as session:
        previous = GENESIS
        query = sa.select(ResultChainRow).where(ResultChainRow.lane == lane).order_by(ResultChainRow.id)
        for link in session.scalars(query).all():
            job = session.get(JobRow, link.job_id)
            assert job is not None
            sweep = session.get(SweepRow, job.sweep_id) if job.sweep_id is not None else None
            link.previous_hash, link.covered = previous, covered_digests(job, sweep)
            link.hash = previous = link_hash_v2(previous, link.covered)
            session.flush()


def test_a_chain_rewritten_from_an_altered_result_on_fails_against_the_heads_log(
    database: Database, tmp_path: Path
) -> None:
    log = heads_log(tmp_path)
    ids = results(database, tmp_path, log, 3)
    with database.engine.begin() as c:
        c.execute(sa.text('UPDATE sweeps SET settings = \'{"vehicle_id": "XY-99"}\''))
    rewrite_chain(database, LANE)
    assert verify_chain(database).problem is None  # every hash recomputed: the chain alone holds

    report = verify_chain(database, checkpoints=log.checkpoints()[0])

    assert report.problem == (
        f"lane 'north': link 1 (job {ids[0]}) is not the one heads log {log.path} line 1 checkpointed (job "
        f"{ids[0]}): the chain was rewritten from there on"
    )


def test_a_line_cut_off_by_a_crash_is_skipped_and_does_not_swallow_the_next(tmp_path: Path) -> None:
    log = heads_log(tmp_path)
    log.path.write_text(
        '{"lane":"north","sequence":1,"job_id":1,"hash":"ab","at":"2026-11-25T08:00:00+00:00"}\n{"lane":"no'
    )
    log.append(Head(LANE, 2, 7, "cd"))
    checkpoints, unreadable = HeadLog(log.path).checkpoints()
    assert [(c.head.sequence, c.head.job_id, c.head.hash) for c in checkpoints] == [
        (1, 1, "ab"),
        (2, 7, "cd"),
    ]
    assert unreadable == 1
    assert checkpoints[1].source == f"heads log {log.path} line 3"


def test_a_heads_log_that_cannot_be_written_leaves_the_result_stored(
    database: Database, tmp_path: Path
) -> None:
    unwritable = HeadLog(tmp_path / "no such folder" / HEADS_FILE)
    [job] = results(database, tmp_path, unwritable, 1)
    assert not unwritable.path.exists()
    assert verify_chain(database).problem is None and verify_chain(database).results == 1
    assert JobStore(database).get(job) is not None


def test_the_central_checkpoints_name_results_deleted_locally_or_centrally(
    local: Database, database: Database, database_url: str, tmp_path: Path
) -> None:
    """`database` is the central database. The lane checkpoints each head there as it pushes the link;
    results deleted from the lane's store fail against them (verify --central), and so do results
    deleted from the central database itself (its own checkpoints)."""
    ids = results(local, tmp_path, None, 3)
    assert len(CentralSync(local, database).push_pending()) == 4  # the sweep, then the three jobs
    with database.sessions() as session:
        marks = session.scalars(sa.select(ChainCheckpointRow).order_by(ChainCheckpointRow.id)).all()
        central_links = session.scalars(sa.select(ResultChainRow).order_by(ResultChainRow.id)).all()
        central_ids = [link.job_id for link in central_links]
    assert [(m.lane, m.sequence, m.job_id) for m in marks] == [
        (LANE, n + 1, job) for n, job in enumerate(ids)
    ]
    assert [m.hash for m in marks] == [link.hash for link in central_links]
    assert [link.sequence for link in central_links] == [1, 2, 3]
    report = verify_chain(database)
    assert (report.problem, report.results, report.checkpoints) == (None, 3, 3)

    delete_results(local, ids[-1:])
    local_file = str(tmp_path / "local.sqlite3")
    done = shockbench("verify", "--database", f"sqlite:///{local_file}", "--central", database_url)
    assert done.returncode == 1
    assert done.stdout.strip() == (
        f"lane 'north': the chain ends at link 2, but the central database's checkpoint {marks[2].id} "
        f"checkpointed link 3 (job {ids[2]}) at {marks[2].checkpointed_at.isoformat(timespec='seconds')}: "
        f"link 3 (job {ids[2]}) is missing (the newest results were removed)"
    )

    delete_results(database, central_ids[-2:])
    problem = verify_chain(database).problem
    assert problem is not None
    assert problem.startswith("lane 'north': the chain ends at link 1, but this database's checkpoint")
    assert f"links 2-3 (jobs {ids[1]}, {ids[2]}) are missing" in problem
