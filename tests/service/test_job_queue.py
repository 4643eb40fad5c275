"""The shared job queue on SQLite and a real PostgreSQL server: every job claimed by exactly one instance
even when instances claim at once, leases renewed and lost, a dead instance's job run again, a job that
keeps killing its instance failed, and a cancel asked on another instance heard by the runner."""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path

import pytest
import sqlalchemy as sa

from service.store.database import Database
from service.store.job_queue import JobQueue
from service.store.jobs import RESTART_REASON, JobFiles, JobStore
from service.store.models import JobRow, JobStatus, utcnow


@pytest.fixture
def database(database_url: str) -> Iterator[Database]:
    database = Database(database_url)
    database.upgrade_schema()
    yield database
    database.dispose()


def submit(store: JobStore, tmp_path: Path, count: int) -> list[int]:
    files = JobFiles(tmp_path / "r.csv", tmp_path / "v.toml", tmp_path)
    return [store.create("identify", {}, lambda _i: files).id for _ in range(count)]


def expire(database: Database, job_id: int) -> None:
    """The lease ran out (as if its instance had stopped renewing it a while ago)."""
    with database.transaction() as session:
        session.execute(
            sa.update(JobRow).where(JobRow.id == job_id).values(lease_until=utcnow() - timedelta(seconds=1))
        )


def test_instances_claiming_at_once_never_share_a_job(database: Database, tmp_path: Path) -> None:
    ids = submit(JobStore(database), tmp_path, 60)
    claims: Counter[int] = Counter()
    by_instance: dict[str, list[int]] = {}
    start = threading.Barrier(4)

    def instance(name: str) -> None:
        queue, mine = JobQueue(database, name), []
        start.wait()
        while (record := queue.claim_next()) is not None:
            assert record.claimed_by == name and record.status is JobStatus.RUNNING
            mine.append(record.id)
        by_instance[name] = mine

    threads = [threading.Thread(target=instance, args=(f"lane-{i}",)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    for mine in by_instance.values():
        claims.update(mine)
        assert mine == sorted(mine)  # each takes the oldest first
    assert sorted(claims) == ids and set(claims.values()) == {1}  # every job exactly once
    assert JobQueue(database, "x").queued_count() == 0


def test_a_dead_instances_job_runs_again_elsewhere_and_its_late_result_is_refused(
    database: Database, tmp_path: Path
) -> None:
    store = JobStore(database)
    (job_id,) = submit(store, tmp_path, 1)
    north, south = JobQueue(database, "north", lease_s=30), JobQueue(database, "south", lease_s=30)
    assert north.claim_next().id == job_id  # type: ignore[union-attr]
    assert north.renew(job_id).held
    assert south.reclaim_expired().requeued == []  # the lease holds: nothing to take back
    expire(database, job_id)
    assert south.reclaim_expired().requeued == [job_id]
    taken = south.claim_next()
    assert taken is not None and taken.id == job_id and taken.attempts == 2 and taken.claimed_by == "south"
    assert not north.renew(job_id).held  # north hears it lost the job ...
    assert not store.succeed(job_id, {"late": True}, {}, None, owner="north")  # ... and cannot end it
    assert store.succeed(job_id, {"x": 1}, {}, None, owner="south")
    assert store.get(job_id).result == {"x": 1}  # type: ignore[union-attr]


def test_a_job_that_keeps_killing_its_instance_is_failed(database: Database, tmp_path: Path) -> None:
    (job_id,) = submit(JobStore(database), tmp_path, 1)
    queue = JobQueue(database, "lane", max_attempts=2)
    for attempt in (1, 2):
        assert queue.claim_next().attempts == attempt  # type: ignore[union-attr]
        expire(database, job_id)
        reclaimed = queue.reclaim_expired()
    assert reclaimed.failed == [job_id] and reclaimed.requeued == []
    record = JobStore(database).get(job_id)
    assert record is not None and record.status is JobStatus.FAILED and record.error == RESTART_REASON


def test_a_cancel_asked_anywhere_reaches_the_runner_and_a_restart_takes_its_own_back(
    database: Database, tmp_path: Path
) -> None:
    first, second = submit(JobStore(database), tmp_path, 2)
    north = JobQueue(database, "north")
    assert north.claim_next().id == first  # type: ignore[union-attr]
    assert not north.renew(first).cancel_requested
    assert JobQueue(database, "south").request_cancel(first)
    assert north.renew(first).cancel_requested
    north_again = JobQueue(database, "north")  # north restarted: its running job comes back at once
    assert north_again.reclaim_own().requeued == [first]
    assert [north_again.claim_next().id, north_again.claim_next().id] == [first, second]  # type: ignore[union-attr]
