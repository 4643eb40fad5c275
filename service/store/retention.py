"""Retention: what clients leave on disk is deleted once it is old, so that the data directory does not
grow for ever (`serve --retain-days`, at start-up and every few hours; `shockbench retention`).

What goes, each file logged with its size and why (one line per file):

- the uploaded inputs (recording CSV, vehicle or model file) of a finished job (succeeded, failed,
  cancelled) that finished more than `retain_days` ago; the job's artefacts (plots, report) stay, they are
  small and the API serves them;
- the recording (HDF5) of a sweep that ended more than `retain_days` ago; its vehicle file (a few kB) stays;
- anything in data_dir/uploads older than `stale_upload_s`: uploads being checked live there for seconds,
  so what is older was left by a crash;
- with `stored_copies`, on a database of this data directory alone (a standalone lane's, or a lane's local
  store), the copy of such a sweep's recording stored in it (service.store.recordings), which would
  otherwise grow the data directory by every recording the lane makes; in a local store only once the
  sweep has reached the central database (it is no longer in the outbox), which keeps its copy. (SQLite
  reuses the pages freed for the next recordings: its file stops growing rather than shrinking.)

What never goes: a file a queued or running job reads (its recording or vehicle file), the recording of a
sweep that a queued or running job analyses or a waiting or running scheduled test waits on, anything of a
sweep that has not ended, anything outside the data directory. Old is judged by the times stored in the
database (a job's or sweep's end), uploads by their files' modification time; both against `now`, which
tests inject.

Every result and its chain link (service.store.result_chain, which covers the results and the recordings'
hashes as the sweeps and jobs hold them, not the files or the stored copies) stays, so `shockbench verify`
passes after retention as before. A central database keeps its stored recordings (`stored_copies` off:
`serve` on a shared database, `shockbench retention --database URL`): it is the fleet's archive
(`shockbench archive`, `reanalyse --database`). What a deleted recording no longer allows: downloading it,
running a new job on it, re-analysing it (`shockbench reanalyse --database` reports that sweep failed: its
recording is not stored).

One residual race, accepted: a job submitted on a sweep older than `retain_days` in the moment between
retention's look at the queue and its deletion fails at its start for want of its recording.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path

from sqlalchemy import and_, delete, func, or_, select
from sqlalchemy.orm import Session
from sqlalchemy.sql.elements import ColumnElement

from service.store.database import Database
from service.store.models import (
    FINISHED_JOBS,
    UNFINISHED_JOBS,
    UNFINISHED_TESTS,
    JobRow,
    RecordingRow,
    ScheduleRow,
    SweepRow,
    SweepStatus,
    SyncOutboxRow,
    utcnow,
)
from service.store.outbox import SWEEP
from service.store.recordings import file_name
from service.store.sweeps import finished

log = logging.getLogger("shockbench.retention")

DEFAULT_RETAIN_DAYS = 90.0
"""A quarter: long enough to look at, download or re-run a test's recording after a complaint or a
re-inspection, short enough to bound the disk (a busy lane's ~50 tests a day of ~1 MB recordings is ~5 GB
a quarter; uploads are bounded by the per-key job quota and the upload size limit)."""
STALE_UPLOAD_S = 24 * 3600.0
"""An upload is copied and checked in seconds (a minute at the most): what is a day old in uploads/ was left
by a crash, and no upload in progress is ever that old."""
ENDED_SWEEPS = tuple(status.value for status in SweepStatus if finished(status))


@dataclass(frozen=True)
class RetentionPolicy:
    retain_days: float = DEFAULT_RETAIN_DAYS
    stale_upload_s: float = STALE_UPLOAD_S
    lanes: tuple[str, ...] | None = None
    """Only jobs and sweeps of these lanes (a database shared by lanes: this instance's and "" for rows from
    before lanes); None: every row (a database of this data directory alone)."""
    stored_copies: bool = False
    """Also the copies of old sweep recordings stored in the database: only for a database of this data
    directory alone (standalone, or a lane's local store). A central database keeps them (the archive)."""

    def __post_init__(self) -> None:
        if not self.retain_days > 0 or not self.stale_upload_s > 0:
            raise ValueError("retain_days and stale_upload_s must be > 0")


@dataclass(frozen=True)
class Removal:
    """A file retention deleted (or, in a dry run, would delete); stored: a recording's copy in the database
    (path: its stored name), not a file."""

    path: Path
    size_bytes: int
    reason: str
    stored: bool = False

    @property
    def what(self) -> str:
        return f"the database's copy of {self.path}" if self.stored else str(self.path)


@dataclass(frozen=True)
class _Candidate:
    path: Path
    reason: str


def _in_lanes(column: object, lanes: tuple[str, ...] | None) -> list[object]:
    return [] if lanes is None else [column.in_(lanes)]  # type: ignore[attr-defined]


def _protected(session: Session) -> tuple[set[str], set[int]]:
    """(files a queued or running job reads, sweeps a queued or running job or an unfinished scheduled test
    needs), on every lane."""
    active = session.execute(
        select(JobRow.recording_path, JobRow.vehicle_path, JobRow.sweep_id).where(
            JobRow.status.in_(UNFINISHED_JOBS)
        )
    ).all()
    paths = {p for recording, vehicle, _ in active for p in (recording, vehicle) if p}
    sweeps = {sweep for _, _, sweep in active if sweep is not None}
    tests = select(ScheduleRow.sweep_id).where(
        ScheduleRow.status.in_(UNFINISHED_TESTS), ScheduleRow.sweep_id.is_not(None)
    )
    sweeps |= {int(s) for s in session.scalars(tests).all()}
    return paths, sweeps


def _older(policy: RetentionPolicy) -> str:
    return f"older than {policy.retain_days:g} days"


def _old_job_inputs(session: Session, cutoff: datetime, policy: RetentionPolicy) -> Iterator[_Candidate]:
    query = select(JobRow.id, JobRow.finished_at, JobRow.recording_path, JobRow.vehicle_path).where(
        JobRow.input_source == "upload",
        JobRow.status.in_(FINISHED_JOBS),
        JobRow.finished_at < cutoff,
        *_in_lanes(JobRow.lane, policy.lanes),
    )
    for job_id, finished_at, *files in session.execute(query.order_by(JobRow.id)):
        why = f"uploaded input of job {job_id}, finished {finished_at:%Y-%m-%d}, {_older(policy)}"
        yield from (_Candidate(Path(f), why) for f in files if f)


def _ended_before(cutoff: datetime) -> ColumnElement[bool]:
    """A sweep that ended before `cutoff` (one that ended without an end time: created before it)."""
    return or_(
        SweepRow.finished_at < cutoff, and_(SweepRow.finished_at.is_(None), SweepRow.created_at < cutoff)
    )


def _old_recordings(
    session: Session, cutoff: datetime, policy: RetentionPolicy, needed: set[int]
) -> Iterator[_Candidate]:
    ended = _ended_before(cutoff)
    query = select(SweepRow.id, SweepRow.finished_at, SweepRow.created_at, SweepRow.recording_path).where(
        SweepRow.status.in_(ENDED_SWEEPS),
        SweepRow.recording_path.is_not(None),
        ended,
        *_in_lanes(SweepRow.lane, policy.lanes),
    )
    for sweep_id, finished_at, created_at, recording in session.execute(query.order_by(SweepRow.id)):
        if sweep_id not in needed:
            when = finished_at or created_at
            why = f"recording of sweep {sweep_id}, ended {when:%Y-%m-%d}, {_older(policy)}"
            yield _Candidate(Path(recording), why)


@dataclass
class _StoredCopy:
    file_name: str
    size_bytes: int
    sweeps: list[int] = field(default_factory=list)
    ended: datetime | None = None
    keep: bool = False


def _old_stored_recordings(
    session: Session, cutoff: datetime, policy: RetentionPolicy, needed: set[int]
) -> list[tuple[int, Removal]]:
    """(row id, removal) of each recording a sweep stored in the database whose every sweep of the same bytes
    (a row is stored once per content) ended before `cutoff`, is not needed and is not waiting in the outbox
    for the central database. A recording imported into the archive (no sweep stored it) stays."""
    waiting = set(session.scalars(select(SyncOutboxRow.row_id).where(SyncOutboxRow.kind == SWEEP)).all())
    old = and_(SweepRow.status.in_(ENDED_SWEEPS), _ended_before(cutoff))
    query = (
        select(RecordingRow.id, RecordingRow.name, RecordingRow.format, func.length(RecordingRow.data))
        .add_columns(SweepRow.id, func.coalesce(SweepRow.finished_at, SweepRow.created_at), old)
        .join(SweepRow, SweepRow.recording_sha256 == RecordingRow.sha256)
        .where(RecordingRow.sweep_uid.is_not(None))
        .order_by(RecordingRow.id, SweepRow.id)
    )
    copies: dict[int, _StoredCopy] = {}
    for row_id, name, file_format, size, sweep_id, ended, is_old in session.execute(query):
        copy = copies.setdefault(row_id, _StoredCopy(file_name(name, file_format), int(size or 0)))
        copy.sweeps.append(sweep_id)
        copy.ended = ended if copy.ended is None else max(copy.ended, ended)
        copy.keep |= not is_old or sweep_id in needed or sweep_id in waiting
    found = []
    for row_id, copy in copies.items():
        if not copy.keep:
            of = ("sweep " if len(copy.sweeps) == 1 else "sweeps ") + ", ".join(str(s) for s in copy.sweeps)
            why = f"stored copy of the recording of {of}, ended {copy.ended:%Y-%m-%d}, {_older(policy)}"
            found.append((row_id, Removal(Path(copy.file_name), copy.size_bytes, why, stored=True)))
    return found


def _stale_uploads(
    uploads: Path, policy: RetentionPolicy, older_than: float
) -> tuple[list[_Candidate], set[Path]]:
    """In one walk of `uploads`: the files last modified before `older_than` (a POSIX time), and the staging
    folders unchanged since then (read before their files are deleted, which makes them look new)."""
    why = f"partial upload left by an interrupted request, older than {policy.stale_upload_s / 3600:g} h"
    found: list[_Candidate] = []
    folders: set[Path] = set()
    for folder, _, names in os.walk(uploads):
        here = Path(folder)
        try:
            if here != uploads and here.stat().st_mtime < older_than:
                folders.add(here)
        except FileNotFoundError:
            continue
        for name in sorted(names):
            path = here / name
            try:
                if path.lstat().st_mtime < older_than:
                    found.append(_Candidate(path, why))
            except FileNotFoundError:
                continue
    return found, folders


def _remove_if_empty(folders: set[Path]) -> None:
    """Each of `folders` that is empty, deepest first (never a folder with anything in it)."""
    for folder in sorted(folders, key=lambda path: -len(path.parts)):
        try:
            folder.rmdir()  # only an empty folder goes
        except OSError:
            continue


def _inside(path: Path, folder: Path) -> bool:
    try:
        return path.resolve().is_relative_to(folder)
    except OSError:
        return False


def run_retention(
    database: Database,
    data_dir: Path,
    policy: RetentionPolicy,
    *,
    now: Callable[[], datetime] = utcnow,
    dry_run: bool = False,
) -> list[Removal]:
    """Delete what `policy` says is old (module docstring); each file logged. Returns what was deleted (in
    a dry run: what would be, nothing deleted). Blocking (database, files): call it in a thread."""
    data_dir = data_dir.resolve()
    moment = now()
    cutoff = moment - timedelta(days=policy.retain_days)
    uploads = data_dir / "uploads"
    stale_before = moment.timestamp() - policy.stale_upload_s
    with database.transaction() as session:
        in_use, needed = _protected(session)
        candidates = [
            *_old_job_inputs(session, cutoff, policy),
            *_old_recordings(session, cutoff, policy, needed),
        ]
        stored = _old_stored_recordings(session, cutoff, policy, needed) if policy.stored_copies else []
        if stored and not dry_run:
            session.execute(delete(RecordingRow).where(RecordingRow.id.in_([i for i, _ in stored])))
    for _, removal in stored:  # logged once the deletion is committed
        what, size = removal.what, removal.size_bytes
        log.info("retention: %s %s (%d bytes): %s", _verb(dry_run), what, size, removal.reason)
    stale_files, stale_folders = _stale_uploads(uploads, policy, stale_before)
    candidates += stale_files
    in_use_resolved = {Path(p).resolve() for p in in_use}
    removals = []
    for candidate in candidates:
        removal = _remove(candidate, data_dir, in_use_resolved, dry_run)
        if removal is not None:
            removals.append(removal)
    if not dry_run:  # the folders of the stale uploads too: an upload in progress is never a day old
        stale_folders |= {r.path.parent for r in removals if r.path.is_relative_to(uploads)}
        _remove_if_empty({folder for folder in stale_folders if folder != uploads})
    removals += [removal for _, removal in stored]
    if removals:
        freed = sum(r.size_bytes for r in removals)
        verb = "would free" if dry_run else "freed"
        log.info("retention: %d file(s), %s %.1f MiB", len(removals), verb, freed / 2**20)
    return removals


def _remove(candidate: _Candidate, data_dir: Path, in_use: set[Path], dry_run: bool) -> Removal | None:
    """Delete the candidate's file (in a dry run, only look at it) unless it is outside the data directory
    or in use; logged."""
    path = candidate.path
    if not _inside(path, data_dir) or path.resolve() in in_use:
        return None
    try:
        if not path.is_file():
            return None  # deleted by an earlier run, or never written
        size = path.stat().st_size
        if not dry_run:
            path.unlink()
    except FileNotFoundError:
        return None
    except OSError as exc:
        log.warning("retention: could not delete %s: %s", path, exc)
        return None
    log.info("retention: %s %s (%d bytes): %s", _verb(dry_run), path, size, candidate.reason)
    return Removal(path, size, candidate.reason)


def _verb(dry_run: bool) -> str:
    return "would delete" if dry_run else "deleted"
