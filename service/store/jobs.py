"""Jobs in the database: submit, move through their states, read back.

Every state change is one conditional UPDATE (`... WHERE status = 'queued'` etc.), so a cancel racing the
start of a job has exactly one winner. Methods are synchronous and short; the asyncio side calls them in a
thread. JobRecord is a detached snapshot of a row, safe to pass around after the session closed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from sqlalchemy import Select, func, select, update
from sqlalchemy.orm import Session

from service.store.chain_anchor import Head, HeadLog
from service.store.database import Database
from service.store.models import UNFINISHED_JOBS, JobRow, JobStatus, utcnow
from service.store.outbox import JOB, queue_finished
from service.store.quota import KeyQuota, QuotaExceededError, enforce
from service.store.result_chain import append_link, recording_sha256

RESTART_REASON = "its service stopped each time it ran"
"""Why a job whose instance died while running it, attempt after attempt, is failed (job_queue)."""
QUOTA_WHAT = "jobs queued or running"


@dataclass(frozen=True)
class JobFiles:
    """Where a job's input is and where its artefacts go."""

    recording_path: Path
    vehicle_path: Path
    output_dir: Path


@dataclass(frozen=True)
class JobRecord:
    id: int
    lane: str
    """The lane it belongs to ("" for rows from before lanes)."""
    kind: str
    status: JobStatus
    options: dict[str, Any]
    input_source: str
    recording_path: str
    vehicle_path: str
    sweep_id: int | None
    output_dir: str
    result: dict[str, Any] | None
    artefacts: dict[str, Any]
    error: str | None
    progress: dict[str, Any] | None
    submitted_by: str | None
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    claimed_by: str | None = None
    """The instance (lane) that runs or ran it."""
    attempts: int = 0
    """How many times it was begun (more than 1: an instance died while running it)."""

    @classmethod
    def of(cls, row: JobRow) -> JobRecord:
        return cls(
            id=row.id,
            lane=row.lane,
            kind=row.kind,
            status=JobStatus(row.status),
            options=dict(row.options or {}),
            input_source=row.input_source,
            recording_path=row.recording_path,
            vehicle_path=row.vehicle_path,
            sweep_id=row.sweep_id,
            output_dir=row.output_dir,
            result=row.result,
            artefacts=dict(row.artefacts or {}),
            error=row.error,
            progress=row.progress,
            submitted_by=row.submitted_by,
            created_at=row.created_at,
            started_at=row.started_at,
            finished_at=row.finished_at,
            claimed_by=row.claimed_by,
            attempts=row.attempts or 0,
        )


class JobStore:
    def __init__(self, database: Database, lane: str = "", heads: HeadLog | None = None) -> None:
        """lane: stamped on every row this store creates (the service's `--lane`); heads: the lane's heads
        log, which every result stored here checkpoints its chain's new head in (chain_anchor)."""
        self.db = database
        self.lane = lane
        self.heads = heads

    def create(
        self,
        kind: str,
        options: dict[str, Any],
        place: Callable[[int], JobFiles],
        *,
        input_source: str = "upload",
        sweep_id: int | None = None,
        submitted_by: str | None = None,
        quota: KeyQuota | None = None,
    ) -> JobRecord:
        """Insert a queued job. `place(job_id)` puts the input where the job will read it (e.g. moves the
        uploaded files into the job's folder) and says where; if it raises, no job is created. With
        `quota`, QuotaExceededError (and no job) when its key would have more unfinished jobs than it allows,
        checked in this transaction (service.store.quota)."""
        with self.db.transaction() as session:
            row = JobRow(
                lane=self.lane,
                kind=kind,
                status=JobStatus.QUEUED.value,
                options=options,
                input_source=input_source,
                sweep_id=sweep_id,
                submitted_by=submitted_by,
                recording_path="",
                vehicle_path="",
                output_dir="",
                artefacts={},
            )
            session.add(row)
            session.flush()
            if quota is not None:
                enforce(session, quota, self._unfinished_of(quota.key_id), QUOTA_WHAT)
            files = place(row.id)
            row.recording_path = str(files.recording_path)
            row.recording_sha256 = recording_sha256(files.recording_path)  # what its chain link covers
            row.vehicle_path = str(files.vehicle_path)
            row.output_dir = str(files.output_dir)
            session.flush()
            return JobRecord.of(row)

    @staticmethod
    def _unfinished_of(key_id: str) -> Select[tuple[int]]:
        """The count of `key_id`'s queued and running jobs (on every lane: the quota is the key's)."""
        where = (JobRow.submitted_by == key_id, JobRow.status.in_(UNFINISHED_JOBS))
        return select(func.count()).select_from(JobRow).where(*where)

    def unfinished_count(self, key_id: str) -> int:
        """How many jobs `key_id` has queued or running."""
        with self.db.sessions() as session:
            return int(session.scalar(self._unfinished_of(key_id)) or 0)

    def check_quota(self, quota: KeyQuota) -> None:
        """QuotaExceededError when `quota`'s key has as many unfinished jobs as it allows already: a cheap
        look before the work of taking a job in (copying and checking an upload). Only a look:
        `create(quota=)` decides, in the transaction that inserts."""
        active = self.unfinished_count(quota.key_id)
        if active >= quota.limit:
            raise QuotaExceededError(QUOTA_WHAT, active, quota.limit)

    def get(self, job_id: int) -> JobRecord | None:
        with self.db.sessions() as session:
            row = session.get(JobRow, job_id)
            return JobRecord.of(row) if row is not None else None

    def list_jobs(
        self,
        *,
        status: JobStatus | None = None,
        kind: str | None = None,
        lane: str | None = None,
        limit: int = 50,
        offset: int = 0,
    ) -> tuple[list[JobRecord], int]:
        """Newest first, and the total count that matches."""
        query = select(JobRow)
        count = select(func.count()).select_from(JobRow)
        if lane is not None:
            query, count = query.where(JobRow.lane == lane), count.where(JobRow.lane == lane)
        if status is not None:
            query, count = (
                query.where(JobRow.status == status.value),
                count.where(JobRow.status == status.value),
            )
        if kind is not None:
            query, count = query.where(JobRow.kind == kind), count.where(JobRow.kind == kind)
        with self.db.sessions() as session:
            rows = session.scalars(query.order_by(JobRow.id.desc()).limit(limit).offset(offset)).all()
            return [JobRecord.of(r) for r in rows], int(session.scalar(count) or 0)

    def latest_of_sweeps(self, sweep_ids: list[int], kind: str) -> dict[int, int]:
        """Sweep id -> the newest job of `kind` on it, for the sweeps that have one."""
        if not sweep_ids:
            return {}
        query = (
            select(JobRow.sweep_id, func.max(JobRow.id))
            .where(JobRow.sweep_id.in_(sweep_ids), JobRow.kind == kind)
            .group_by(JobRow.sweep_id)
        )
        with self.db.sessions() as session:
            return {int(sweep): int(job) for sweep, job in session.execute(query).all()}

    def queued_ids(self) -> list[int]:
        """Queued jobs in the order they were submitted."""
        with self.db.sessions() as session:
            query = select(JobRow.id).where(JobRow.status == JobStatus.QUEUED.value).order_by(JobRow.id)
            return list(session.scalars(query).all())

    def _transition(
        self,
        job_id: int,
        from_status: tuple[JobStatus, ...],
        owner: str | None = None,
        *,
        then: Callable[[Session, int], object] | None = None,
        **values: Any,
    ) -> bool:
        """One conditional UPDATE: from one of `from_status` (and, with `owner`, only while that instance
        holds the claim: one whose lease was taken over must not write the job's end); when it changed
        the row, `then(session, job_id)` in the same transaction."""
        where = [JobRow.id == job_id, JobRow.status.in_([s.value for s in from_status])]
        if owner is not None:
            where.append(JobRow.claimed_by == owner)
        with self.db.transaction() as session:
            done = session.execute(update(JobRow).where(*where).values(**values))
            if done.rowcount == 1 and then is not None:
                then(session, job_id)
            if done.rowcount == 1 and JobStatus(values.get("status", JobStatus.RUNNING)).finished:
                queue_finished(self.db, session, JOB, [job_id])
            return done.rowcount == 1

    def mark_running(self, job_id: int, owner: str | None = None) -> bool:
        """queued -> running (one more attempt, claimed by `owner`); False when the job is no longer queued
        (cancelled meanwhile). The service claims jobs through service.store.job_queue instead."""
        return self._transition(
            job_id,
            (JobStatus.QUEUED,),
            status=JobStatus.RUNNING.value,
            started_at=utcnow(),
            progress=None,
            claimed_by=owner,
            attempts=JobRow.attempts + 1,
        )

    def requeue(self, job_id: int, owner: str | None = None) -> bool:
        """running -> queued, not counted as an attempt: the job never really started (its worker died
        before taking it), or the service is stopping and another instance, or its next start, resumes
        it."""
        return self._transition(
            job_id,
            (JobStatus.RUNNING,),
            owner,
            status=JobStatus.QUEUED.value,
            started_at=None,
            progress=None,
            claimed_by=None,
            lease_until=None,
            attempts=JobRow.attempts - 1,
        )

    def set_progress(self, job_id: int, progress: dict[str, Any], owner: str | None = None) -> None:
        self._transition(job_id, (JobStatus.RUNNING,), owner, progress=progress)

    def succeed(
        self,
        job_id: int,
        result: dict[str, Any],
        artefacts: dict[str, Any],
        progress: dict[str, Any] | None,
        owner: str | None = None,
    ) -> bool:
        """running -> succeeded with the result, chained to the lane's previous result in the same
        transaction (service.store.result_chain); the new head is then checkpointed in the heads log."""
        heads: list[Head] = []
        done = self._transition(
            job_id,
            (JobStatus.RUNNING,),
            owner,
            then=lambda session, job: heads.append(append_link(session, job)),
            status=JobStatus.SUCCEEDED.value,
            result=result,
            artefacts=artefacts,
            progress=progress,
            finished_at=utcnow(),
        )
        if done and self.heads is not None:  # after the commit: a head rolled back is never logged
            self.heads.record(heads[0])
        return done

    def fail(
        self, job_id: int, reason: str, progress: dict[str, Any] | None = None, owner: str | None = None
    ) -> bool:
        values: dict[str, Any] = {"status": JobStatus.FAILED.value, "error": reason, "finished_at": utcnow()}
        if progress is not None:
            values["progress"] = progress
        return self._transition(job_id, (JobStatus.QUEUED, JobStatus.RUNNING), owner, **values)

    def cancel(
        self,
        job_id: int,
        reason: str = "cancelled",
        *,
        running: bool = False,
        progress: dict[str, Any] | None = None,
        owner: str | None = None,
    ) -> bool:
        """Queued (or, with running=True, running) -> cancelled."""
        allowed = (JobStatus.QUEUED, JobStatus.RUNNING) if running else (JobStatus.QUEUED,)
        values: dict[str, Any] = {
            "status": JobStatus.CANCELLED.value,
            "error": reason,
            "finished_at": utcnow(),
        }
        if progress is not None:
            values["progress"] = progress
        return self._transition(job_id, allowed, owner, **values)
