"""Recordings in the database (issue 33, item 1): a sweep's recording is stored with it (bytes, sha256,
vehicle text) and synced with it to the central database exactly once; the stored bytes are what the
result chain's recording hash names, so altering them fails `verify`; a database of the previous schema
keeps its chain verifying through the migration; a recording written twice is stored once."""

from __future__ import annotations

import hashlib
import zlib
from pathlib import Path

import sqlalchemy as sa

from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import RecordingRow, SweepStatus
from service.store.recordings import NONE, ZLIB, RecordingStore, pack, unpack
from service.store.result_chain import verify_chain
from service.store.schema import head_revision, upgrade
from service.store.sweeps import SweepStore
from service.store.sync import CentralSync

LANE = "north"
CSV = "t,x_s,x_t,x_r\n" + "".join(f"{i / 1000:.3f},{i * 1e-6:.9e},0,0\n" for i in range(2000))
VEHICLE = 'mass_kg = 420.0\nvehicle = "quarter car"\n'


def sweep_with_result(local: Database, tmp: Path) -> tuple[int, str]:
    """A complete sweep whose recording file and vehicle file exist, and an identification succeeded on
    it (chained); (sweep id, the recording's sha256)."""
    store = SweepStore(local, lane=LANE)

    def place(sweep_id: int) -> tuple[Path, Path]:
        recording, vehicle = tmp / f"{sweep_id}.csv", tmp / f"{sweep_id}.vehicle.toml"
        recording.write_text(CSV)
        vehicle.write_text(VEHICLE)
        return recording, vehicle

    sweep = store.create("bench", {"vehicle_id": "AB-1"}, place)
    assert store.mark_running(sweep.id)
    assert store.finish(sweep.id, SweepStatus.COMPLETE, complete=True, reason=None)
    jobs = JobStore(local, lane=LANE)
    files = JobFiles(tmp / f"{sweep.id}.csv", tmp / f"{sweep.id}.vehicle.toml", tmp)
    job = jobs.create("identify", {}, lambda _i: files, sweep_id=sweep.id)
    assert jobs.mark_running(job.id, owner=LANE)
    assert jobs.succeed(job.id, {"gap_m": 1e-5}, {}, None, owner=LANE)
    return sweep.id, hashlib.sha256(CSV.encode()).hexdigest()


def test_a_sweeps_recording_goes_into_the_database_and_to_the_central_one_once(
    local: Database, database: Database, tmp_path: Path
) -> None:
    sweep_id, sha256 = sweep_with_result(local, tmp_path)
    (stored,) = RecordingStore(local).listing()
    assert (stored.sha256, stored.name, stored.format, stored.compression) == (
        sha256,
        f"sweep-{sweep_id}",
        "csv",
        ZLIB,
    )
    assert (stored.vehicle_text, stored.vehicle_id) == (VEHICLE, "AB-1")
    assert stored.stored_bytes < stored.size_bytes / 2  # a CSV compresses
    assert RecordingStore(local).content(sha256) == CSV.encode()
    assert SweepStore(local).get(sweep_id) is not None

    sync = CentralSync(local, database)
    assert [p.kind for p in sync.push_pending()] == ["sweep", "job"]
    with local.sessions() as session:  # a push repeated after the central commit changes nothing
        from service.store.models import SyncOutboxRow
        from service.store.outbox import JOB

        session.add(SyncOutboxRow(kind=JOB, row_id=1))
        session.commit()
    sync.push_pending()
    (central,) = RecordingStore(database).listing()
    assert (central.sha256, central.vehicle_text, central.sweep_uid) == (sha256, VEHICLE, stored.sweep_uid)
    assert RecordingStore(database).content(sha256) == CSV.encode()
    assert verify_chain(database).problem is None


def test_an_altered_stored_recording_fails_verify(local: Database, tmp_path: Path) -> None:
    _, sha256 = sweep_with_result(local, tmp_path)
    assert verify_chain(local).problem is None
    altered = zlib.compress(CSV.replace("0.001,", "0.002,", 1).encode())
    with local.transaction() as session:
        session.execute(sa.update(RecordingRow).values(data=altered))
    problem = verify_chain(local).problem
    assert problem == f"recording sweep-1 ({sha256[:12]}) was altered: its bytes no longer match its sha256"

    # bytes and hash rewritten together: the sweep's chained recording hash still names the old bytes
    new_hash = hashlib.sha256(zlib.decompress(altered)).hexdigest()
    with local.transaction() as session:
        session.execute(sa.update(RecordingRow).values(sha256=new_hash))
    assert "is not the one its sweep's chained recording hash names" in str(verify_chain(local).problem)


def test_the_previous_schema_migrates_with_its_chain_verifying(database_url: str, tmp_path: Path) -> None:
    database = Database(database_url)
    try:
        upgrade(database.engine, to="0006")
        store = JobStore(database, lane=LANE)
        job = store.create("identify", {}, lambda _i: JobFiles(tmp_path / "r.csv", tmp_path / "v", tmp_path))
        assert store.mark_running(job.id) and store.succeed(job.id, {"gap_m": 3e-5}, {}, None)
        before = verify_chain(database)
        assert before.problem is None and before.results == 1
        assert database.upgrade_schema() == ("0006", head_revision())
        after = verify_chain(database)
        assert (after.problem, after.results) == (None, 1)
        assert RecordingStore(database).listing() == []
    finally:
        database.dispose()


def test_the_same_bytes_are_stored_once(database: Database) -> None:
    store = RecordingStore(database)
    first = store.put(CSV.encode(), name="a", file_format="csv", vehicle_text=VEHICLE)
    again = store.put(CSV.encode(), name="b", file_format="csv", vehicle_text=None)
    assert first.created and not again.created and first.sha256 == again.sha256
    assert [r.name for r in store.listing()] == ["a"]


def test_hdf5_is_kept_as_it_is_unless_zlib_saves_a_tenth() -> None:
    noise = bytes(hashlib.sha256(str(i).encode()).digest()[0] for i in range(20_000))  # incompressible
    assert pack(noise, "h5") == (NONE, noise)
    compression, data = pack(b"\0" * 20_000, "h5")
    assert compression == ZLIB and unpack(compression, data) == b"\0" * 20_000
