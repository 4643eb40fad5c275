"""Retention (issue 30, item 3): old uploaded inputs, old sweep recordings and stale partial uploads are
deleted, each logged with its size and why; a recording a queued job still needs is kept; the results stay
verifiable (`shockbench verify`). Old is judged against an injected clock or a file's set mtime: no
sleeps."""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path

import pytest
from live_server import LiveServer
from sqlalchemy import delete, select

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.quotas import retention_policy
from service.cli import retention as retention_cli
from service.cli.main import main
from service.store import retention
from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import RecordingRow, SweepRow, SweepStatus, SyncOutboxRow, utcnow
from service.store.retention import RetentionPolicy, run_retention
from service.store.sweeps import SweepStore

DAY_S = 24 * 3600.0


def put(path: Path, size: int, age_s: float = 0.0, fill: bytes = b"x") -> Path:
    """A file of `size` bytes, last modified `age_s` ago."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(fill * size)
    if age_s:
        stamp = time.time() - age_s
        os.utime(path, (stamp, stamp))
    return path


class Bench:
    """A data directory with its SQLite database: an uploaded job that succeeded, a sweep that ended, a
    sweep whose identification is still queued, and a crash's partial upload. local_store: the database is
    a lane's local store (its finished sweeps wait in the outbox for the central database)."""

    def __init__(self, data_dir: Path, local_store: bool = False, url: str | None = None) -> None:
        self.data_dir = data_dir
        self.database = Database(url or f"sqlite:///{data_dir / 'shockbench.sqlite3'}", outbox=local_store)
        self.database.upgrade_schema()
        jobs, sweeps = JobStore(self.database, lane="L"), SweepStore(self.database, lane="L")

        folder = data_dir / "jobs" / "000001-abcd"
        self.upload = [put(folder / "recording.csv", 3000), put(folder / "vehicle.toml", 200)]
        self.plot = put(folder / "plot.png", 100)
        job = jobs.create(
            "identify", {}, lambda _i: JobFiles(*self.upload, folder), input_source="upload", submitted_by="k"
        )
        assert jobs.mark_running(job.id) and jobs.succeed(
            job.id, {"answer": 42}, {"plot.png": "plot.png"}, None
        )

        def sweep(fill: bytes) -> tuple[int, Path]:
            record = sweeps.create(
                "bench",
                {"vehicle_id": "AB-1"},
                lambda i: (
                    put(data_dir / "sweeps" / f"{i}.h5", 5000, fill=fill),
                    put(data_dir / "sweeps" / f"{i}.vehicle.toml", 50),
                ),
            )
            assert sweeps.finish(record.id, SweepStatus.COMPLETE, complete=True, reason=None)
            return record.id, Path(str(record.recording_path))

        self.old_sweep, self.recording = sweep(b"x")
        # an old sweep whose recording has the same bytes as the needed one's: stored once, so kept
        self.twin_sweep, self.twin = sweep(b"y")
        self.needed_sweep, self.needed = needed_sweep, _ = sweep(b"y")
        vehicle = data_dir / "sweeps" / f"{needed_sweep}.vehicle.toml"
        jobs.create(  # queued, not run: its recording must stay
            "identify",
            {},
            lambda i: JobFiles(self.needed, vehicle, data_dir / "jobs" / f"{i:06d}"),
            input_source="sweep",
            sweep_id=needed_sweep,
        )
        self.stale = put(data_dir / "uploads" / "upload-dead" / "recording.csv", 700, age_s=2 * DAY_S)
        self.fresh = put(data_dir / "uploads" / "upload-live" / "recording.csv", 900, age_s=60)


@pytest.fixture
def bench(tmp_path: Path) -> Iterator[Bench]:
    made = Bench(tmp_path / "data")
    yield made
    made.database.dispose()


def stored_sweeps(database: Database) -> list[int]:
    """The ids of the sweeps that stored the recordings the database holds (a recording is stored once per
    content, by the first sweep that recorded it)."""
    with database.sessions() as session:
        query = select(SweepRow.id).join(RecordingRow, RecordingRow.sweep_uid == SweepRow.uid)
        return sorted(session.scalars(query).all())


def test_a_local_store_keeps_a_recordings_copy_until_it_reached_the_central_database(
    tmp_path: Path, database_url: str
) -> None:
    """In a lane's local store the copy goes only once its sweep has been pushed (left the outbox); a
    central database (stored_copies off) is the fleet's archive and keeps every copy. The service and the
    command choose stored_copies for the data directory's own database only. On SQLite and PostgreSQL."""
    bench = Bench(tmp_path / "data", local_store=True, url=database_url)
    later = lambda: utcnow() + timedelta(days=91)  # noqa: E731
    try:
        for policy in (RetentionPolicy(90, stored_copies=True), RetentionPolicy(90, lanes=("L", ""))):
            removed = run_retention(bench.database, bench.data_dir, policy, now=later)
            assert not any(r.stored for r in removed)
            assert stored_sweeps(bench.database) == [bench.old_sweep, bench.twin_sweep]
        with bench.database.transaction() as session:  # the old sweep pushed, as CentralSync does
            session.execute(
                delete(SyncOutboxRow).where(
                    SyncOutboxRow.kind == "sweep", SyncOutboxRow.row_id == bench.old_sweep
                )
            )
        central = RetentionPolicy(90, lanes=("L", ""))
        assert run_retention(bench.database, bench.data_dir, central, now=later) == []
        own = RetentionPolicy(90, stored_copies=True)
        (copy,) = run_retention(bench.database, bench.data_dir, own, now=later)
        assert copy.stored and copy.path == Path(f"sweep-{bench.old_sweep}.h5")
        assert stored_sweeps(bench.database) == [bench.twin_sweep]
    finally:
        bench.database.dispose()
    own, local, shared = (
        retention_policy(ServiceSettings(data_dir=tmp_path, keys=KeyRing({}), retain_days=90.0, **more))
        for more in ({}, {"database_url": "sqlite://", "local_store": True}, {"database_url": "sqlite://"})
    )
    assert own and local and shared
    assert own.stored_copies and local.stored_copies and not shared.stored_copies


def test_retention_deletes_old_inputs_and_recordings_keeps_what_is_needed_and_logs_each(
    bench: Bench, caplog: pytest.LogCaptureFixture
) -> None:
    policy = RetentionPolicy(retain_days=90, stored_copies=True)
    caplog.set_level(logging.INFO, logger="shockbench.retention")

    today = run_retention(bench.database, bench.data_dir, policy, now=utcnow)
    assert [r.path for r in today] == [bench.stale]  # only the crash's leftover is old yet
    assert not bench.stale.parent.exists() and bench.fresh.is_file()

    later = lambda: utcnow() + timedelta(days=91)  # noqa: E731
    dry = run_retention(bench.database, bench.data_dir, policy, now=later, dry_run=True)
    assert all(path.is_file() for path in [*bench.upload, bench.recording])  # a dry run deletes nothing
    caplog.clear()
    assert stored_sweeps(bench.database) == [bench.old_sweep, bench.twin_sweep]  # a dry run keeps them
    removed = run_retention(bench.database, bench.data_dir, policy, now=later)
    assert removed == dry
    *files, copy = removed
    assert [r.path for r in files] == [*bench.upload, bench.recording, bench.twin, bench.fresh]
    assert [r.size_bytes for r in files] == [3000, 200, 5000, 5000, 900]
    # the database's copy of the old sweep's recording goes too; the one the needed sweep shares stays
    assert copy.stored and copy.path == Path(f"sweep-{bench.old_sweep}.h5") and copy.size_bytes > 0
    assert f"stored copy of the recording of sweep {bench.old_sweep}," in copy.reason
    assert stored_sweeps(bench.database) == [bench.twin_sweep]
    assert not any(path.exists() for path in [*bench.upload, bench.recording, bench.fresh])
    assert bench.needed.is_file()  # its sweep's identification is still queued
    assert bench.plot.is_file() and bench.recording.with_suffix(".vehicle.toml").is_file()
    assert "uploaded input of job 1" in removed[0].reason and "older than 90 days" in removed[0].reason
    assert f"recording of sweep {bench.old_sweep}" in removed[2].reason

    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("retention: deleted")]
    assert len(lines) == 6
    assert f"retention: deleted the database's copy of sweep-{bench.old_sweep}.h5 (" in lines[0]
    lines = lines[1:]
    assert lines[0] == f"retention: deleted {bench.upload[0]} (3000 bytes): {removed[0].reason}"
    assert lines[2].startswith(f"retention: deleted {bench.recording} (5000 bytes): recording of sweep")
    assert run_retention(bench.database, bench.data_dir, policy, now=later) == []  # nothing left to do


def test_results_stay_verifiable_after_retention(bench: Bench, capsys: pytest.CaptureFixture[str]) -> None:
    later = lambda: utcnow() + timedelta(days=91)  # noqa: E731
    assert run_retention(bench.database, bench.data_dir, RetentionPolicy(90), now=later)
    capsys.readouterr()
    assert main(["verify", "--data", str(bench.data_dir)]) == 0
    assert "1 results in 1 lane verified" in capsys.readouterr().out


def test_the_retention_command_lists_then_deletes(bench: Bench, capsys: pytest.CaptureFixture[str]) -> None:
    data = str(bench.data_dir)
    assert main(["retention", "--data", data, "--dry-run"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [
        f"would delete {bench.stale} (700 bytes): partial upload left by an interrupted request, older "
        "than 24 h",
        "1 file(s), 0.0 MiB to free",
    ]
    assert bench.stale.is_file()
    assert main(["retention", "--data", data]) == 0
    assert capsys.readouterr().out.startswith(f"deleted {bench.stale} (700 bytes)")
    assert not bench.stale.exists() and bench.fresh.is_file() and bench.recording.is_file()
    assert main(["retention", "--data", data, "--retain-days", "0"]) == 2
    assert retention_cli.DEFAULT_RETAIN_DAYS == retention.DEFAULT_RETAIN_DAYS


def test_the_service_runs_retention_at_start_up(tmp_path: Path) -> None:
    """A crash's partial upload is gone once the service is up; with --retain-days 0 it is kept."""
    kept = put(tmp_path / "off" / "uploads" / "upload-dead" / "recording.csv", 10, age_s=2 * DAY_S)
    stale = put(tmp_path / "on" / "uploads" / "upload-dead" / "recording.csv", 10, age_s=2 * DAY_S)
    keys = KeyRing({"operator-key-0123456789": Role.OPERATOR})
    for data_dir, days in ((tmp_path / "on", 90.0), (tmp_path / "off", None)):
        with LiveServer(create_app(ServiceSettings(data_dir=data_dir, keys=keys, retain_days=days))):
            pass
    assert not stale.exists() and kept.is_file()
