"""The tables: jobs (identification and diagnosis), sweeps, scheduled tests, the result chain and its
checkpoints, and the archive: stored recordings and re-analysis runs with their results (issue 33).

SQLAlchemy 2.x declarative models with portable column types only (strings, integers, floats, booleans,
JSON, timestamps), so the same models work on SQLite and PostgreSQL. Statuses are stored as their string
values. Timestamps are UTC; SQLite forgets the zone, so `UTCDateTime` puts it back on reading.
"""

from __future__ import annotations

import uuid
from datetime import UTC, datetime
from enum import StrEnum
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
    false,
)
from sqlalchemy.engine import Dialect
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column
from sqlalchemy.types import TypeDecorator


def utcnow() -> datetime:
    return datetime.now(UTC)


def new_uid() -> str:
    """A row's global identity (service.store.sync): a random UUID, the same in a lane's local store and
    in the central database, where the row's integer id differs."""
    return str(uuid.uuid4())


class UTCDateTime(TypeDecorator[datetime]):
    """A timezone-aware UTC timestamp on every back end."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is not None and value.tzinfo is None:
            raise ValueError("naive datetime given to a UTC column")
        return value.astimezone(UTC) if value is not None else None

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is not None and value.tzinfo is None:
            return value.replace(tzinfo=UTC)
        return value


class JobKind(StrEnum):
    IDENTIFY = "identify"
    DIAGNOSE = "diagnose"
    VALIDATE = "validate"


class JobStatus(StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def finished(self) -> bool:
        return self in (JobStatus.SUCCEEDED, JobStatus.FAILED, JobStatus.CANCELLED)


class SweepStatus(StrEnum):
    REQUESTED = "requested"
    RUNNING = "running"
    COMPLETE = "complete"
    FAILED = "failed"
    ABORTED = "aborted"


class ScheduleStatus(StrEnum):
    WAITING = "waiting"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"


UNFINISHED_JOBS = (JobStatus.QUEUED.value, JobStatus.RUNNING.value)
"""Stored statuses of jobs not yet ended: what a key's quota counts and what retention keeps."""
FINISHED_JOBS = tuple(status.value for status in JobStatus if status.finished)
UNFINISHED_TESTS = (ScheduleStatus.WAITING.value, ScheduleStatus.RUNNING.value)
"""Stored statuses of scheduled tests not yet ended."""


class Base(DeclarativeBase):
    type_annotation_map = {datetime: UTCDateTime, dict[str, Any]: JSON}  # noqa: RUF012 - SQLAlchemy API


class SweepRow(Base):
    """A sweep on the bench (filled in by the acquisition layer). Its recording is written to its file, and
    kept in `recordings` too when the sweep ends (service.store.sweeps)."""

    __tablename__ = "sweeps"
    __table_args__ = (
        Index("ix_sweeps_lane", "lane"),
        Index("uq_sweeps_uid", "uid", unique=True),
        {"sqlite_autoincrement": True},  # ids never reused
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    uid: Mapped[str | None] = mapped_column(String(36), default=new_uid)
    """Global identity: the same in the lane's local store and the central database (service.store.sync)."""
    bench: Mapped[str] = mapped_column(String(100), default="default")
    lane: Mapped[str] = mapped_column(String(100), default="", server_default="")
    """The lane (`serve --lane`) whose bench ran it; "" for rows from before lanes."""
    status: Mapped[str] = mapped_column(String(16), default=SweepStatus.REQUESTED.value)
    settings: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    """Sweep settings as submitted (frequencies, amplitude, duration ...)."""
    vehicle_file: Mapped[str | None] = mapped_column(Text, default=None)
    recording_path: Mapped[str | None] = mapped_column(Text, default=None)
    recording_sha256: Mapped[str | None] = mapped_column(String(64), default=None)
    """sha256 (hex) of the recording file's bytes when the sweep ended (SweepStore.finish); None when it
    left no file, or it ended otherwise (a restart) or before revision 0006. A result's chain link covers
    it (service.store.result_chain)."""
    complete: Mapped[bool] = mapped_column(Boolean, default=False)
    """True when the recording holds the whole sweep without gaps."""
    reason: Mapped[str | None] = mapped_column(Text, default=None)
    """Why the sweep failed or was aborted (emergency stop, device fault, restart)."""
    operator: Mapped[str | None] = mapped_column(String(64), default=None)
    """Key id of who requested it (service.access.key_id)."""
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(default=None)
    finished_at: Mapped[datetime | None] = mapped_column(default=None)


class JobRow(Base):
    """An identification or diagnosis job. Its input is either uploaded files (kept in the job's folder in
    the data directory) or a sweep's recording; the result is the estimator's JSON."""

    __tablename__ = "jobs"
    __table_args__ = (
        Index("ix_jobs_status", "status"),
        Index("ix_jobs_lane", "lane"),
        Index("uq_jobs_uid", "uid", unique=True),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    """Increasing: the submission order, which is the order jobs run in (FIFO)."""
    uid: Mapped[str | None] = mapped_column(String(36), default=new_uid)
    """Global identity: the same in the lane's local store and the central database (service.store.sync)."""
    origin_id: Mapped[int | None] = mapped_column(Integer, default=None)
    """On the central database, a job synced from a lane's local store: its id there, which its result
    chain link hashes (service.store.result_chain); None for a job stored where it was submitted."""
    lane: Mapped[str] = mapped_column(String(100), default="", server_default="")
    """The lane it was submitted on; "" for rows from before lanes."""
    kind: Mapped[str] = mapped_column(String(16), default=JobKind.IDENTIFY.value)
    status: Mapped[str] = mapped_column(String(16), default=JobStatus.QUEUED.value)
    options: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    input_source: Mapped[str] = mapped_column(String(16), default="upload")
    """'upload' (files in the job folder) or 'sweep' (the recording of sweep_id)."""
    recording_path: Mapped[str] = mapped_column(Text)
    recording_sha256: Mapped[str | None] = mapped_column(String(64), default=None)
    """sha256 (hex) of the bytes of the recording file at `recording_path` when the job was submitted; None
    when there was no such file, or for jobs from before revision 0006. Its chain link covers it."""
    vehicle_path: Mapped[str] = mapped_column(Text)
    sweep_id: Mapped[int | None] = mapped_column(ForeignKey("sweeps.id"), default=None)
    output_dir: Mapped[str] = mapped_column(Text)
    """Folder for the job's artefacts (plots)."""
    result: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    artefacts: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    """Artefact name -> file name inside output_dir (e.g. {"plot.png": "plot.png"})."""
    error: Mapped[str | None] = mapped_column(Text, default=None)
    progress: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    submitted_by: Mapped[str | None] = mapped_column(String(64), default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(default=None)
    finished_at: Mapped[datetime | None] = mapped_column(default=None)
    claimed_by: Mapped[str | None] = mapped_column(String(100), default=None)
    """The instance (its lane) running it; set when claimed (service.store.job_queue)."""
    lease_until: Mapped[datetime | None] = mapped_column(default=None)
    """The claim holds until then unless renewed; past it, any instance may run the job again."""
    attempts: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    """How many times it was begun: a job whose instance keeps dying is failed after a few."""
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())
    """Cancel asked while it runs (on any instance); the running instance sees it at its next renewal."""


class ScheduleRow(Base):
    """A scheduled inspection-line test: a vehicle file and sweep settings, to run at `run_at` or, when
    that is None, as soon as the bench is free. One test runs at a time per bench."""

    __tablename__ = "schedules"
    __table_args__ = (
        Index("ix_schedules_bench_status", "bench", "status"),
        Index("ix_schedules_lane", "lane"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    bench: Mapped[str] = mapped_column(String(100), default="default")
    lane: Mapped[str] = mapped_column(String(100), default="", server_default="")
    """The lane whose scheduler runs it; "" for rows from before lanes."""
    vehicle_file: Mapped[str] = mapped_column(Text)
    sweep_settings: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    job_options: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    """Options of the identification job run on the sweep's recording."""
    run_at: Mapped[datetime | None] = mapped_column(default=None)
    """When to run; None = when the bench is free."""
    status: Mapped[str] = mapped_column(String(16), default=ScheduleStatus.WAITING.value)
    sweep_id: Mapped[int | None] = mapped_column(ForeignKey("sweeps.id"), default=None)
    job_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id"), default=None)
    reason: Mapped[str | None] = mapped_column(Text, default=None)
    created_by: Mapped[str | None] = mapped_column(String(64), default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(default=None)
    finished_at: Mapped[datetime | None] = mapped_column(default=None)


class ResultChainRow(Base):
    """One link of a lane's result chain (service.store.result_chain): the content hash of a succeeded job's
    result with what it means (its vehicle, sweep, recording, thresholds), chained to the lane's previous
    link, appended in the transaction that stores the result."""

    __tablename__ = "result_chain"
    __table_args__ = (
        UniqueConstraint("job_id", name="uq_result_chain_job"),
        UniqueConstraint("lane", "previous_hash", name="uq_result_chain_lane_previous"),  # no forks
        Index("ix_result_chain_lane_id", "lane", "id"),
        Index("uq_result_chain_lane_sequence", "lane", "sequence", unique=True),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    """Increasing along each lane's chain (appends are serialized per lane)."""
    lane: Mapped[str] = mapped_column(String(100))
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"))
    previous_hash: Mapped[str] = mapped_column(String(64))
    """The lane's previous link's hash; 64 zeros for its first."""
    hash: Mapped[str] = mapped_column(String(64))
    """sha256 (hex) of the canonical record (service.store.result_chain), by the formula of link_version."""
    link_version: Mapped[int] = mapped_column(Integer, server_default="1")
    """The link's format: 1 for links written before revision 0006, 2 since (service.store.result_chain)."""
    covered: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    """Version 2: covered field -> sha256 (hex) of its canonical JSON, which the hash covers; None in 1."""
    sequence: Mapped[int | None] = mapped_column(Integer, default=None)
    """The link's place in its lane's chain, 1 for the first: what a checkpoint names (chain_anchor)."""
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class ChainCheckpointRow(Base):
    """A lane's chain head as the lane checkpointed it on the central database when it pushed the link
    (service.store.sync, service.store.chain_anchor): `verify` fails when the chain of that lane ends
    before it. Rows are only ever inserted."""

    __tablename__ = "chain_checkpoints"
    __table_args__ = (
        Index("uq_chain_checkpoints_lane_sequence", "lane", "sequence", unique=True),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    lane: Mapped[str] = mapped_column(String(100))
    sequence: Mapped[int] = mapped_column(Integer)
    """The head link's place in the lane's chain (1 for the first)."""
    job_id: Mapped[int] = mapped_column(Integer)
    """The head's job, by the id it has where it ran (the one its link hashes), not a reference here."""
    hash: Mapped[str] = mapped_column(String(64))
    checkpointed_at: Mapped[datetime] = mapped_column(default=utcnow)


class SyncOutboxRow(Base):
    """A lane's local store: a finished sweep or job waiting to be pushed to the central database, in the
    order of `seq` (service.store.sync). Empty and unused elsewhere."""

    __tablename__ = "sync_outbox"
    __table_args__ = ({"sqlite_autoincrement": True},)

    seq: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    kind: Mapped[str] = mapped_column(String(16))
    """"sweep" or "job"."""
    row_id: Mapped[int] = mapped_column(Integer)
    """The row's id in the local store."""
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class RecordingRow(Base):
    """A recording kept in the database (service.store.recordings, issue 33): its file's bytes, compressed
    when that saves space, named by the sha256 of the file's bytes (the same hash a sweep's and a job's
    `recording_sha256` hold, which their chain links cover), with its vehicle file's text. Stored once per
    content: the archive's identity is the hash, not the name."""

    __tablename__ = "recordings"
    __table_args__ = (
        UniqueConstraint("sha256", name="uq_recordings_sha256"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    sha256: Mapped[str] = mapped_column(String(64))
    """sha256 (hex) of the recording file's bytes as they were (before compression)."""
    name: Mapped[str] = mapped_column(Text)
    """Its name: the path it was imported from relative to the archive folder, or sweep-<id>.h5."""
    format: Mapped[str] = mapped_column(String(8))
    """The file's suffix without the dot (csv, h5, hdf5): how `archive export` names it."""
    compression: Mapped[str] = mapped_column(String(8))
    """"zlib" or "none" (an HDF5 recording compresses its data inside; zlib would gain little)."""
    size_bytes: Mapped[int] = mapped_column(Integer)
    """The file's size."""
    data: Mapped[bytes] = mapped_column(LargeBinary)
    """The file's bytes, compressed as `compression` says."""
    vehicle_text: Mapped[str | None] = mapped_column(Text, default=None)
    """Its vehicle file's text; None for an HDF5 recording that carries its own."""
    vehicle_id: Mapped[str | None] = mapped_column(String(200), default=None)
    """Which vehicle it tested (a sweep's settings["vehicle_id"], an imported one's vehicle file's name):
    what `reanalyse --compare` groups by."""
    sweep_uid: Mapped[str | None] = mapped_column(String(36), default=None)
    """The sweep it was recorded by (its global uid); None for an imported recording."""
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class ReanalysisRunRow(Base):
    """One re-analysis of the stored recordings (`shockbench reanalyse --database`): which software with
    which options, when, and how it went."""

    __tablename__ = "reanalysis_runs"
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    software_version: Mapped[str] = mapped_column(String(64))
    options: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    """The analyses and their options ({"analyses": [...], "tyre", "points"})."""
    started_at: Mapped[datetime] = mapped_column(default=utcnow)
    finished_at: Mapped[datetime | None] = mapped_column(default=None)
    """None while it runs (or when it was interrupted)."""
    recordings: Mapped[int] = mapped_column(Integer, default=0)
    succeeded: Mapped[int] = mapped_column(Integer, default=0)
    failed: Mapped[int] = mapped_column(Integer, default=0)


class ReanalysisResultRow(Base):
    """One analysis of one recording in a run: the command's JSON, or why it failed. At most one per run,
    recording and analysis: a retried task's second write is refused by the constraint and ignored."""

    __tablename__ = "reanalysis_results"
    __table_args__ = (
        UniqueConstraint("run_id", "recording_sha256", "analysis", name="uq_reanalysis_results_once"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("reanalysis_runs.id"))
    recording_sha256: Mapped[str] = mapped_column(String(64))
    analysis: Mapped[str] = mapped_column(String(16))
    """identify or diagnose."""
    result: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    reason: Mapped[str | None] = mapped_column(Text, default=None)
    """Why it failed (one line); None when it succeeded."""
    seconds: Mapped[float] = mapped_column(Float, default=0.0)
    """Worker wall time, reading included."""
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
