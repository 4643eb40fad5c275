"""Lanes in the store, on SQLite and PostgreSQL: each instance stamps its lane on what it creates, lists
filter by lane, the vehicle-id search works on both back ends, and a lane's scheduler claims only its own
lane's tests."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import JobKind
from service.store.schedules import ScheduleStore
from service.store.sweeps import SweepStore


@pytest.fixture
def database(database_url: str) -> Iterator[Database]:
    database = Database(database_url)
    database.upgrade_schema()
    yield database
    database.dispose()


def test_each_lane_stamps_and_finds_its_own(database: Database, tmp_path: Path) -> None:
    place = lambda i: (tmp_path / f"{i}.h5", tmp_path / f"{i}.toml")  # noqa: E731
    north, south = SweepStore(database, lane="north"), SweepStore(database, lane="south")
    a = north.create("bench", {"vehicle_id": "AB-123"}, place)
    b = south.create("bench", {"vehicle_id": "ab-123"}, place)
    c = south.create("bench", {"vehicle_id": "XY-9"}, place)
    assert (a.lane, b.lane, c.lane) == ("north", "south", "south")
    assert [s.id for s in north.list_sweeps(lane="south")[0]] == [c.id, b.id]
    assert [s.id for s in north.list_sweeps(vehicle_id="AB-123")[0]] == [b.id, a.id]  # across lanes
    assert north.list_sweeps(vehicle_id="ab-123", lane="north")[1] == 1

    files = JobFiles(tmp_path / "r.csv", tmp_path / "v.toml", tmp_path)
    jobs_north, jobs_south = JobStore(database, lane="north"), JobStore(database, lane="south")
    first = jobs_north.create(JobKind.IDENTIFY.value, {}, lambda _i: files, sweep_id=a.id)
    second = jobs_south.create(JobKind.IDENTIFY.value, {}, lambda _i: files, sweep_id=a.id)
    jobs_south.create(JobKind.DIAGNOSE.value, {}, lambda _i: files, sweep_id=a.id)
    assert [j.id for j in jobs_north.list_jobs(lane="north")[0]] == [first.id]
    assert jobs_north.latest_of_sweeps([a.id, b.id], JobKind.IDENTIFY.value) == {a.id: second.id}


def test_a_lanes_scheduler_claims_only_its_own_tests(database: Database, tmp_path: Path) -> None:
    now = datetime.now(UTC) + timedelta(days=1)
    north, south = ScheduleStore(database, lane="north"), ScheduleStore(database, lane="south")
    south_test = south.create("bench", {}, {}, None, lambda i: tmp_path / f"{i}.toml")
    assert north.claim_next("bench", now) is None  # same bench name, other lane: not north's to run
    north_test = north.create("bench", {}, {}, None, lambda i: tmp_path / f"{i}.toml")
    claimed = north.claim_next("bench", now)
    assert claimed is not None and claimed.id == north_test.id and claimed.lane == "north"
    assert south.running("bench") is None  # north's running test does not block south
    claimed = south.claim_next("bench", now)
    assert claimed is not None and claimed.id == south_test.id
    assert [t.id for t in north.list_tests(lane="south")[0]] == [south_test.id]
