"""A lane's local store synced to the central database: the lane keeps testing when the central database
is away, and the central database gets every finished sweep and job exactly once, in order.

Design (README "A lane keeps testing when the central database is away"):

- With `serve --database URL` the lane runs on its local store, SQLite in its data directory: its sweeps,
  jobs, scheduled tests, results and result chain are written there first, with local ids, and its API
  answers from there. Its jobs run on its own worker from its local queue: a job is never both in a local
  queue and claimable on the central database, because the central database only ever receives it
  finished (`serve --shared-queue` instead runs the lane on the central database alone, with item 4's
  shared queue, and then needs the central database up). Not handing the lane's jobs to the shared queue
  while the central database answers is deliberate: the lane's result chain has one writer, its local
  store, and another instance chaining one of the lane's results on the central database would fork it.
- Every sweep and job that reaches its final state joins the local outbox (service.store.outbox) in the
  transaction that finishes it: `seq` orders the entries as they finished, which is also the order of the
  lane's result chain.
- `CentralSync.push_pending` pushes the entries oldest first, one central transaction each, and removes an
  entry from the outbox only after the central transaction committed. A row is matched on the central
  database by its global identity `uid` (a UUID, unique there), never by its id: a push repeated because the
  connection died between the central commit and the outbox removal updates the same row to the same
  values, so each row arrives exactly once. A job's sweep is pushed with it when it is not there yet (the
  job's `sweep_id` is the central id of that sweep).
- The result chain stays verifiable on the central database (`shockbench verify --database URL`): a synced
  job keeps its local id as `origin_id`, which its link hashes, and its link is appended there with the
  lane's hashes unchanged, after checking that it follows the central chain's newest link of its lane (one
  lane, one store: a lane whose links also reach the central database another way would fork its chain;
  the push stops with that error in the sync status instead). In the same transaction the lane checkpoints
  its chain's new head there (`chain_checkpoints`, service.store.chain_anchor), so that removing the
  lane's newest results, locally or centrally, fails `verify`.
- A sweep's recording goes with it: the bytes, sha256 and vehicle text its lane's store keeps
  (service.store.recordings, issue 33) are inserted on the central database unless a recording of the same
  sha256 is there already (idempotent by content), in the transaction that pushes the sweep. Other files
  stay on the lane: the central rows carry the paths of vehicle files and job artefacts as they are on the
  lane's machine.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from sqlalchemy import delete, insert, select, update
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session

from estimator.errors import one_line
from service.store.chain_anchor import Head, checkpoint_central
from service.store.database import Database
from service.store.models import JobRow, RecordingRow, ResultChainRow, SweepRow, SyncOutboxRow
from service.store.outbox import JOB, SWEEP
from service.store.result_chain import chained_job_id, locked_head


class SyncError(RuntimeError):
    """A finished row the central database cannot take as it is (one line); the push stops there."""


class LocalStoreError(RuntimeError):
    """The local store failed while the outbox was read or an entry removed (one line); nothing is lost:
    the entry is pushed again (idempotent) at the next try."""


@contextmanager
def _local_store() -> Iterator[None]:
    try:
        yield
    except SQLAlchemyError as exc:
        raise LocalStoreError(f"local store: {one_line(exc)}") from exc


def _values(row: SweepRow | JobRow | RecordingRow, leave_out: set[str]) -> dict[str, Any]:
    return {c.name: getattr(row, c.key) for c in row.__table__.columns if c.name not in leave_out}


def _upsert(session: Session, model: type[SweepRow] | type[JobRow], values: dict[str, Any]) -> int:
    """The central row of `values["uid"]`, inserted or brought to `values`; its central id."""
    central_id = session.scalar(select(model.id).where(model.uid == values["uid"]))
    if central_id is None:
        return int(session.execute(insert(model).values(**values).returning(model.id)).scalar_one())
    session.execute(update(model).where(model.id == central_id).values(**values))
    return int(central_id)


@dataclass(frozen=True)
class Pushed:
    kind: str
    local_id: int
    central_id: int


class CentralSync:
    """Pushes a lane's local outbox to the central database (module docstring)."""

    def __init__(self, local: Database, central: Database) -> None:
        self.local = local
        self.central = central
        self.pushed = 0
        """Entries pushed and removed from the outbox by this object (also those of a call that raised)."""

    def push_pending(self, limit: int | None = None) -> list[Pushed]:
        """Push the outbox oldest first (at most `limit` entries); what was pushed. Raises what the
        central database raises (unreachable, dropped) or SyncError; what was pushed before stays pushed."""
        pushed: list[Pushed] = []
        while limit is None or len(pushed) < limit:
            with _local_store(), self.local.sessions() as session:
                entry = session.scalars(select(SyncOutboxRow).order_by(SyncOutboxRow.seq).limit(1)).first()
            if entry is None:
                break
            pushed.append(self.push_entry(entry))
            with _local_store(), self.local.transaction() as session:  # only after the central commit
                session.execute(delete(SyncOutboxRow).where(SyncOutboxRow.seq == entry.seq))
            self.pushed += 1
        return pushed

    def push_entry(self, entry: SyncOutboxRow) -> Pushed:
        """One entry: its rows read from the local store, then written in one central transaction
        (idempotent: see the module docstring)."""
        with _local_store(), self.local.sessions() as local:
            found = _Rows.read(local, entry)
        with self.central.transaction() as central:
            if found.recording is not None:
                _push_recording(central, found.recording)
            if found.job is None:
                assert found.sweep is not None
                return Pushed(SWEEP, found.sweep.id, _push_sweep(central, found.sweep))
            central_id = _push_job(central, found.job, found.sweep)
            if found.link is not None:
                head = _push_link(central, found.link, central_id, chained_job_id(found.job))
                if head is not None:
                    checkpoint_central(central, head)
            return Pushed(JOB, found.job.id, central_id)


@dataclass(frozen=True)
class _Rows:
    """What one outbox entry pushes, read from the local store: a sweep, or a job with its sweep (if it
    ran on one) and its chain link (if it succeeded); the sweep's stored recording, if there is one."""

    sweep: SweepRow | None
    job: JobRow | None = None
    link: ResultChainRow | None = None
    recording: RecordingRow | None = None

    @staticmethod
    def recording_of(local: Session, sweep: SweepRow | None) -> RecordingRow | None:
        if sweep is None or sweep.recording_sha256 is None:
            return None
        return local.scalar(select(RecordingRow).where(RecordingRow.sha256 == sweep.recording_sha256))

    @classmethod
    def read(cls, local: Session, entry: SyncOutboxRow) -> _Rows:
        if entry.kind == SWEEP:
            sweep = local.get(SweepRow, entry.row_id)
            if sweep is None:
                raise SyncError(f"sweep {entry.row_id} of the outbox is not in the local store")
            return cls(sweep, recording=cls.recording_of(local, sweep))
        if entry.kind != JOB:
            raise SyncError(f"outbox entry {entry.seq} has an unknown kind {entry.kind!r}")
        job = local.get(JobRow, entry.row_id)
        if job is None:
            raise SyncError(f"job {entry.row_id} of the outbox is not in the local store")
        sweep = None
        if job.sweep_id is not None:
            sweep = local.get(SweepRow, job.sweep_id)
            if sweep is None:
                raise SyncError(f"job {job.id}'s sweep {job.sweep_id} is not in the local store")
        link = local.scalar(select(ResultChainRow).where(ResultChainRow.job_id == job.id))
        return cls(sweep, job, link, cls.recording_of(local, sweep))


def _push_recording(central: Session, recording: RecordingRow) -> None:
    """The recording on the central database, unless its sha256 is there (idempotent by content)."""
    if central.scalar(select(RecordingRow.id).where(RecordingRow.sha256 == recording.sha256)) is None:
        central.execute(insert(RecordingRow).values(**_values(recording, {"id"})))


def _push_sweep(central: Session, sweep: SweepRow) -> int:
    if sweep.uid is None:
        raise SyncError(f"sweep {sweep.id} has no uid (schema older than revision 0005?)")
    return _upsert(central, SweepRow, _values(sweep, {"id"}))


def _push_job(central: Session, job: JobRow, sweep: SweepRow | None) -> int:
    """The job's central row (its sweep's first, when it ran on one); its central id."""
    if job.uid is None:
        raise SyncError(f"job {job.id} has no uid (schema older than revision 0005?)")
    values = _values(job, {"id", "sweep_id", "origin_id", "lease_until"})
    values["origin_id"] = job.origin_id if job.origin_id is not None else job.id
    values["sweep_id"] = _push_sweep(central, sweep) if sweep is not None else None
    return _upsert(central, JobRow, values)


def _push_link(central: Session, link: ResultChainRow, central_job_id: int, chained_id: int) -> Head | None:
    """Append the lane's link to the central chain, unless it is there (a repeated push: None); the lane's
    new head there (`chained_id`: the job id the link hashes)."""
    if central.scalar(select(ResultChainRow.id).where(ResultChainRow.job_id == central_job_id)):
        return None
    tip = locked_head(central, link.lane)
    if tip.hash != link.previous_hash:
        raise SyncError(
            f"lane {link.lane!r}: the central chain ends at {tip.hash[:12]}, but this lane's next link "
            f"(job {link.job_id}) follows {link.previous_hash[:12]}: another store wrote this lane's "
            "results there; sync stopped"
        )
    central.add(
        ResultChainRow(
            lane=link.lane,
            job_id=central_job_id,
            previous_hash=link.previous_hash,
            hash=link.hash,
            link_version=link.link_version,
            covered=link.covered,
            sequence=tip.sequence + 1,  # the lane's numbering: the same chain, link for link
            created_at=link.created_at,
        )
    )
    central.flush()
    return Head(link.lane, tip.sequence + 1, chained_id, link.hash)
