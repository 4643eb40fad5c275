"""The scheduled-test store on its own, on SQLite and on a real PostgreSQL server: which test is due, in
what order, one running per bench, and that everything survives reopening the database (a restart)."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from service.store.database import Database
from service.store.models import ScheduleStatus
from service.store.schedules import ScheduleStore
from service.store.sweeps import SweepStore

T0 = datetime.now(UTC).replace(microsecond=0) + timedelta(days=1)
"""'Now' for the store: a day after the tests were submitted (their created_at is the real clock)."""


@pytest.fixture
def database(database_url: str) -> Iterator[Database]:
    database = Database(database_url)
    database.upgrade_schema()
    yield database
    database.dispose()


@pytest.fixture
def store(database: Database) -> ScheduleStore:
    return ScheduleStore(database)


def add(store: ScheduleStore, folder: Path, run_at: datetime | None, bench: str = "lane 1") -> int:
    record = store.create(
        bench, {"duration_s": 20}, {}, run_at, lambda i: folder / f"{i}.toml", created_by="admin-id"
    )
    assert record.status is ScheduleStatus.WAITING and record.vehicle_file == str(
        folder / f"{record.id}.toml"
    )
    return record.id


def test_due_tests_run_one_at_a_time_earliest_due_first(
    store: ScheduleStore, database: Database, tmp_path: Path
) -> None:
    sweep = SweepStore(database).create("lane 1", {}, lambda i: (tmp_path / f"{i}.h5", tmp_path / f"{i}.v"))
    later = add(store, tmp_path, T0 + timedelta(hours=2))
    asap = add(store, tmp_path, None)
    early = add(store, tmp_path, T0 - timedelta(days=3650))  # due long before `asap` was submitted
    other_lane = add(store, tmp_path, None, bench="lane 2")

    first = store.claim_next("lane 1", T0)
    assert first is not None and first.id == early and first.status is ScheduleStatus.RUNNING
    assert first.started_at is not None
    assert store.claim_next("lane 1", T0) is None, "a second test started while one runs"
    assert store.running("lane 1") == store.get(early)
    lane2 = store.claim_next("lane 2", T0)
    assert lane2 is not None and lane2.id == other_lane, "benches are independent"

    assert store.attach_sweep(early, sweep.id) and store.finish(early, ScheduleStatus.DONE)
    assert not store.finish(early, ScheduleStatus.FAILED, reason="late"), "an ended test changed again"
    done = store.get(early)
    assert done is not None and (done.status, done.sweep_id) == (ScheduleStatus.DONE, sweep.id)

    second = store.claim_next("lane 1", T0)
    assert second is not None and second.id == asap
    assert store.release(asap), "an operator's sweep took the bench: back to waiting"
    assert store.get(asap).status is ScheduleStatus.WAITING  # type: ignore[union-attr]
    again = store.claim_next("lane 1", T0)
    assert again is not None and again.id == asap
    store.finish(asap, ScheduleStatus.FAILED, reason="sweep 8 failed: exciter fault")

    assert store.claim_next("lane 1", T0 + timedelta(hours=1, minutes=59)) is None, "ran before its time"
    timed = store.claim_next("lane 1", T0 + timedelta(hours=2))
    assert timed is not None and timed.id == later


def test_only_waiting_tests_cancel_and_everything_survives_a_reopen(
    tmp_path: Path, database_url: str
) -> None:
    database = Database(database_url)
    database.upgrade_schema()
    store = ScheduleStore(database)
    waiting = add(store, tmp_path, T0)
    running = add(store, tmp_path, None)
    assert store.claim_next("lane 1", T0 - timedelta(minutes=1)).id == running  # type: ignore[union-attr]
    assert not store.cancel(running), "a running test was cancelled instead of its sweep aborted"
    with pytest.raises(ValueError, match="not how a running test ends"):
        store.finish(running, ScheduleStatus.CANCELLED)
    database.dispose()

    reopened = ScheduleStore(Database(database_url))
    tests, total = reopened.list_tests()
    assert total == 2 and [t.id for t in tests] == [running, waiting]
    assert tests[1].run_at == T0 and tests[1].run_at.tzinfo is not None
    assert tests[0].status is ScheduleStatus.RUNNING and tests[0].created_by == "admin-id"
    assert reopened.cancel(waiting)
    cancelled = reopened.get(waiting)
    assert cancelled is not None and cancelled.status is ScheduleStatus.CANCELLED
    assert cancelled.reason == "cancelled before it began" and cancelled.finished_at is not None
    assert reopened.list_tests(status=ScheduleStatus.CANCELLED)[1] == 1
