"""A lane's local store (SQLite) pushed to a central database (SQLite and a real PostgreSQL server):
finished sweeps and jobs arrive in order, exactly once even when a push is repeated after the central
commit, with the sweep a job ran on; the lane's result chain verifies on the central database; a central
chain the lane's links do not follow stops the push; an unreachable central database keeps the backlog."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import sqlalchemy as sa
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from service.store.database import Database
from service.store.job_queue import JobQueue
from service.store.jobs import JobFiles, JobStore
from service.store.models import JobRow, JobStatus, SweepRow, SweepStatus, SyncOutboxRow, utcnow
from service.store.outbox import backlog
from service.store.result_chain import verify_chain
from service.store.schema import upgrade
from service.store.sweeps import SweepStore
from service.store.sync import CentralSync, LocalStoreError, SyncError

LANE = "north"


def finished_sweep(local: Database, tmp: Path) -> int:
    store = SweepStore(local, lane=LANE)
    sweep = store.create("bench", {"vehicle_id": "AB-1"}, lambda i: (tmp / f"{i}.h5", tmp / f"{i}.toml"))
    assert store.mark_running(sweep.id)
    assert store.finish(sweep.id, SweepStatus.COMPLETE, complete=True, reason=None)
    return sweep.id


def finished_job(local: Database, tmp: Path, gap_m: float | None, sweep_id: int | None = None) -> int:
    """A job run to its end: succeeded with a result (`gap_m`), or failed when gap_m is None."""
    store = JobStore(local, lane=LANE)
    files = JobFiles(tmp / "r.csv", tmp / "v.toml", tmp)
    job = store.create("identify", {"points": 20}, lambda _i: files, sweep_id=sweep_id)
    assert store.mark_running(job.id, owner=LANE)
    if gap_m is None:
        assert store.fail(job.id, "diverged", owner=LANE)
    else:
        assert store.succeed(job.id, {"gap_m": gap_m}, {}, None, owner=LANE)
    return job.id


def central_rows(central: Database) -> tuple[list[SweepRow], list[JobRow]]:
    with central.sessions() as session:
        sweeps = list(session.scalars(sa.select(SweepRow).order_by(SweepRow.id)).all())
        jobs = list(session.scalars(sa.select(JobRow).order_by(JobRow.id)).all())
    return sweeps, jobs


def test_finished_rows_arrive_in_order_exactly_once(
    local: Database, database: Database, tmp_path: Path
) -> None:
    first = finished_job(local, tmp_path, 1e-5)
    sweep = finished_sweep(local, tmp_path)
    on_sweep = finished_job(local, tmp_path, 2e-5, sweep_id=sweep)
    failed = finished_job(local, tmp_path, None)
    JobStore(local, lane=LANE).create("identify", {}, lambda _i: JobFiles(tmp_path, tmp_path, tmp_path))
    assert backlog(local).count == 4  # the queued job waits for its end
    sync = CentralSync(local, database)

    pushed = sync.push_pending()

    assert [(p.kind, p.local_id) for p in pushed] == [
        ("job", first),
        ("sweep", sweep),
        ("job", on_sweep),
        ("job", failed),
    ]
    assert (backlog(local).count, backlog(local).oldest) == (0, None)
    sweeps, jobs = central_rows(database)
    assert [s.uid for s in sweeps] == [_uid(local, SweepRow, sweep)]
    assert [j.origin_id for j in jobs] == [first, on_sweep, failed]
    assert [j.status for j in jobs] == ["succeeded", "succeeded", "failed"]
    assert jobs[1].sweep_id == sweeps[0].id and jobs[1].result == {"gap_m": 2e-5}
    assert all(j.lane == LANE and j.attempts == 1 for j in jobs)
    assert JobQueue(database, "south").claim_next() is None  # the queued job stayed local: nothing to claim
    assert verify_chain(database).problem is None and verify_chain(database).results == 2

    # the connection died after the central commit, before the outbox entries were removed: pushed again
    with local.transaction() as session:
        for kind, row_id in (("job", first), ("sweep", sweep), ("job", on_sweep)):
            session.add(SyncOutboxRow(kind=kind, row_id=row_id))
    assert len(sync.push_pending()) == 3
    again_sweeps, again_jobs = central_rows(database)
    assert [s.id for s in again_sweeps] == [s.id for s in sweeps]
    assert [j.id for j in again_jobs] == [j.id for j in jobs]
    assert verify_chain(database).results == 2 and verify_chain(database).problem is None


def _uid(database: Database, model: type[SweepRow] | type[JobRow], row_id: int) -> str | None:
    with database.sessions() as session:
        return session.scalar(sa.select(model.uid).where(model.id == row_id))


def test_an_altered_synced_result_is_named_on_the_central_database(
    local: Database, database: Database, tmp_path: Path
) -> None:
    ids = [finished_job(local, tmp_path, 1e-5 * (i + 1)) for i in range(3)]
    CentralSync(local, database).push_pending()
    assert verify_chain(database).results == 3
    with database.transaction() as session:
        session.execute(sa.update(JobRow).where(JobRow.origin_id == ids[1]).values(result={"gap_m": 0.5}))
        altered = session.scalar(sa.select(JobRow.id).where(JobRow.origin_id == ids[1]))
    problem = verify_chain(database).problem
    assert problem is not None and f"job {altered}'s stored result was altered" in problem


def test_a_central_chain_the_lane_does_not_follow_stops_the_push(
    local: Database, database: Database, tmp_path: Path
) -> None:
    finished_job(database, tmp_path, 9e-5)  # the lane's results reached the central database another way
    mine = finished_job(local, tmp_path, 1e-5)
    with pytest.raises(SyncError, match="another store wrote this lane's results"):
        CentralSync(local, database).push_pending()
    assert backlog(local).count == 1  # kept: nothing of it reached the central database
    _, jobs = central_rows(database)
    assert [j.origin_id for j in jobs] == [None]
    assert _uid(local, JobRow, mine) not in {j.uid for j in jobs}


def test_an_unreachable_central_database_keeps_the_backlog(local: Database, tmp_path: Path) -> None:
    finished_job(local, tmp_path, 1e-5)
    away = Database("postgresql+psycopg://postgres@127.0.0.1:9/none?connect_timeout=2")
    with pytest.raises(OperationalError):
        CentralSync(local, away).push_pending()
    assert backlog(local).count == 1
    with local.sessions() as session:
        assert session.scalar(sa.select(JobRow.status)) == JobStatus.SUCCEEDED.value


def test_rows_stored_before_the_sync_revision_get_their_own_uid(database_url: str) -> None:
    database = Database(database_url)
    try:
        upgrade(database.engine, to="0004")
        with database.engine.begin() as c:
            for _ in range(3):
                c.execute(
                    sa.text(
                        "INSERT INTO sweeps (bench, lane, status, settings, complete, created_at) "
                        "VALUES ('b', 'north', 'complete', '{}', true, :t)"
                    ),
                    {"t": utcnow()},
                )
        upgrade(database.engine)
        with database.sessions() as session:
            uids = session.scalars(sa.select(SweepRow.uid)).all()
        assert len(uids) == 3 and len(set(uids)) == 3 and all(uids)
    finally:
        database.dispose()


def test_a_push_whose_acknowledgement_is_lost_is_repeated_without_a_duplicate(
    local: Database, database: Database, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The second entry's central transaction commits, then the local store fails to remove it (as when
    the lane dies between the two): it is pushed again at the next try, and stays one row."""
    ids = [finished_job(local, tmp_path, 1e-5 * (i + 1)) for i in range(3)]
    sync = CentralSync(local, database)
    real, acks = local.transaction, []

    @contextmanager
    def second_ack_fails() -> Iterator[Session]:
        acks.append(1)
        if len(acks) == 2:
            raise OperationalError("DELETE FROM sync_outbox", {}, Exception("disk I/O error"))
        with real() as session:
            yield session

    monkeypatch.setattr(local, "transaction", second_ack_fails)
    with pytest.raises(LocalStoreError, match=r"local store: .*disk I/O error"):
        sync.push_pending()
    monkeypatch.undo()
    assert sync.pushed == 1 and backlog(local).count == 2
    assert [j.origin_id for j in central_rows(database)[1]] == ids[:2]  # the second is there already

    assert [p.local_id for p in sync.push_pending()] == ids[1:]
    assert [j.origin_id for j in central_rows(database)[1]] == ids  # once each
    assert verify_chain(database).problem is None and verify_chain(database).results == 3
