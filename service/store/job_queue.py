"""The job queue every instance of the service shares through the database: exactly one instance claims
each job, holds it by a lease it renews, and a job whose instance died is run again by another.

- `claim_next`: the oldest queued job, taken in one transaction. On PostgreSQL the row is locked with
  `FOR UPDATE SKIP LOCKED`, so instances claiming at the same moment each get a different job without
  waiting for each other; SQLite has one writer at a time, so the conditional UPDATE alone decides.
  Why row locks and no queue library: the jobs already live in this table with their state, results and
  events; a second store (a broker, a queue library's own tables) would have to be kept in step with it.
- `renew`: the running instance extends its lease (every `lease_s / 3`); the answer also says whether a
  cancel was asked on some instance (`request_cancel`).
- `reclaim_expired`: any instance puts a job whose lease ran out back in the queue; after
  `max_attempts` begun runs it is failed instead (a job that kills its service must not loop).
- `reclaim_own`: at start, an instance takes back at once what its previous run of the same lane held
  (a lane runs one instance; a crash of it need not wait for the lease).
- A claim is the instance's name (its lane); the job's end is written only while the claim is still
  that instance's (service.store.jobs: `owner=`), so an instance that lost its lease (paused, cut off)
  cannot overwrite the run another instance took over.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import timedelta

from sqlalchemy import func, or_, select, update

from service.service_limits import WorkerLimits
from service.store.database import Database
from service.store.jobs import RESTART_REASON, JobRecord
from service.store.models import JobRow, JobStatus, utcnow
from service.store.outbox import JOB, queue_finished

DEFAULT_LEASE_S: float = WorkerLimits.job_lease_s
"""A claim not renewed for this long is taken to be dead (the renewal comes every third of it); declared in
service.service_limits."""
DEFAULT_MAX_ATTEMPTS = 3


@dataclass(frozen=True)
class Renewal:
    held: bool
    """The claim is still this instance's (False: the lease ran out and the job was taken back)."""
    cancel_requested: bool


@dataclass(frozen=True)
class Reclaimed:
    requeued: list[int]
    failed: list[int]
    """Begun `max_attempts` times, each time cut off: failed with RESTART_REASON."""


class JobQueue:
    def __init__(
        self,
        database: Database,
        instance: str,
        lease_s: float = DEFAULT_LEASE_S,
        max_attempts: int = DEFAULT_MAX_ATTEMPTS,
    ) -> None:
        if not instance:
            raise ValueError("a queue needs the instance's name")
        if not lease_s > 0 or max_attempts < 1:
            raise ValueError("lease_s must be > 0 and max_attempts >= 1")
        self.db = database
        self.instance = instance
        self.lease_s = lease_s
        self.max_attempts = max_attempts

    def _lease(self) -> timedelta:
        return timedelta(seconds=self.lease_s)

    def claim_next(self) -> JobRecord | None:
        """The oldest queued job, now running here (one more attempt); None when the queue is empty."""
        with self.db.transaction() as session:
            job_id = session.scalar(
                select(JobRow.id)
                .where(JobRow.status == JobStatus.QUEUED.value)
                .order_by(JobRow.id)
                .limit(1)
                .with_for_update(skip_locked=True)
            )
            if job_id is None:
                return None
            now = utcnow()
            taken = session.execute(
                update(JobRow)
                .where(JobRow.id == job_id, JobRow.status == JobStatus.QUEUED.value)
                .values(
                    status=JobStatus.RUNNING.value,
                    started_at=now,
                    progress=None,
                    claimed_by=self.instance,
                    lease_until=now + self._lease(),
                    attempts=JobRow.attempts + 1,
                    cancel_requested=False,
                )
            )
            if taken.rowcount != 1:
                return None
            row = session.get(JobRow, job_id, populate_existing=True)
            return JobRecord.of(row) if row is not None else None

    def renew(self, job_id: int) -> Renewal:
        """Extend this instance's lease on a running job; says whether it still holds it and whether a
        cancel was asked."""
        with self.db.transaction() as session:
            renewed = session.execute(
                update(JobRow)
                .where(
                    JobRow.id == job_id,
                    JobRow.status == JobStatus.RUNNING.value,
                    JobRow.claimed_by == self.instance,
                )
                .values(lease_until=utcnow() + self._lease())
            )
            cancel = session.scalar(select(JobRow.cancel_requested).where(JobRow.id == job_id))
            return Renewal(held=renewed.rowcount == 1, cancel_requested=bool(cancel))

    def request_cancel(self, job_id: int) -> bool:
        """Ask the instance running `job_id` to cancel it (it sees it at its next renewal)."""
        with self.db.transaction() as session:
            done = session.execute(
                update(JobRow)
                .where(JobRow.id == job_id, JobRow.status == JobStatus.RUNNING.value)
                .values(cancel_requested=True)
            )
            return done.rowcount == 1

    def queued_count(self) -> int:
        with self.db.sessions() as session:
            count = session.scalar(
                select(func.count()).select_from(JobRow).where(JobRow.status == JobStatus.QUEUED.value)
            )
            return int(count or 0)

    def reclaim_expired(self) -> Reclaimed:
        """Running jobs whose lease ran out (or that have none: written by an older shockbench) back to
        the queue, or failed once begun `max_attempts` times."""
        expired = or_(JobRow.lease_until.is_(None), JobRow.lease_until < utcnow())
        return self._reclaim(expired)

    def reclaim_own(self) -> Reclaimed:
        """At start: what this instance's lane held before (its previous run died) back to the queue."""
        return self._reclaim(or_(JobRow.claimed_by == self.instance, JobRow.lease_until.is_(None)))

    def _reclaim(self, condition: object) -> Reclaimed:
        running = JobRow.status == JobStatus.RUNNING.value
        with self.db.transaction() as session:
            rows = session.execute(
                select(JobRow.id, JobRow.attempts)
                .where(running, condition)  # type: ignore[arg-type]
                .order_by(JobRow.id)
                .with_for_update(skip_locked=True)
            ).all()
            spent = [job_id for job_id, attempts in rows if (attempts or 0) >= self.max_attempts]
            again = [job_id for job_id, attempts in rows if (attempts or 0) < self.max_attempts]
            if spent:
                session.execute(
                    update(JobRow)
                    .where(JobRow.id.in_(spent), running)
                    .values(status=JobStatus.FAILED.value, error=RESTART_REASON, finished_at=utcnow())
                )
                queue_finished(self.db, session, JOB, spent)
            if again:
                session.execute(
                    update(JobRow)
                    .where(JobRow.id.in_(again), running)
                    .values(
                        status=JobStatus.QUEUED.value,
                        started_at=None,
                        progress=None,
                        claimed_by=None,
                        lease_until=None,
                    )
                )
            return Reclaimed(requeued=again, failed=spent)
