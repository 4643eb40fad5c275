"""Scheduled inspection-line tests in the database: waiting -> running -> done / failed, or cancelled while
waiting.

A test is a vehicle file plus sweep settings (and the options of the identification job run on its
recording), due at `run_at` or, when that is None, as soon as the bench is free. Like the other stores,
every state change is one conditional UPDATE in its own short session, so the methods are safe from any
thread, and taking the next due test (`claim_next`) cannot hand the same test out twice.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from sqlalchemy import func, select, update

from service.store.database import Database
from service.store.models import UNFINISHED_TESTS, ScheduleRow, ScheduleStatus, utcnow
from service.store.quota import KeyQuota, enforce

FINISHED = (ScheduleStatus.DONE, ScheduleStatus.FAILED, ScheduleStatus.CANCELLED)


@dataclass(frozen=True)
class ScheduleRecord:
    id: int
    lane: str
    """The lane it belongs to ("" for rows from before lanes)."""
    bench: str
    status: ScheduleStatus
    vehicle_file: str
    """Path of the vehicle file saved in the data directory at submit."""
    sweep_settings: dict[str, Any]
    job_options: dict[str, Any]
    run_at: datetime | None
    sweep_id: int | None
    job_id: int | None
    reason: str | None
    created_by: str | None
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None

    @property
    def finished(self) -> bool:
        return self.status in FINISHED

    @classmethod
    def of(cls, row: ScheduleRow) -> ScheduleRecord:
        return cls(
            id=row.id,
            lane=row.lane,
            bench=row.bench,
            status=ScheduleStatus(row.status),
            vehicle_file=row.vehicle_file,
            sweep_settings=dict(row.sweep_settings or {}),
            job_options=dict(row.job_options or {}),
            run_at=row.run_at,
            sweep_id=row.sweep_id,
            job_id=row.job_id,
            reason=row.reason,
            created_by=row.created_by,
            created_at=row.created_at,
            started_at=row.started_at,
            finished_at=row.finished_at,
        )


class ScheduleStore:
    def __init__(self, database: Database, lane: str = "") -> None:
        """lane: stamped on every row this store creates (the service's `--lane`)."""
        self.db = database
        self.lane = lane

    def create(
        self,
        bench: str,
        sweep_settings: dict[str, Any],
        job_options: dict[str, Any],
        run_at: datetime | None,
        place: Callable[[int], Path],
        *,
        created_by: str | None = None,
        quota: KeyQuota | None = None,
    ) -> ScheduleRecord:
        """Insert a waiting test. `place(test_id)` saves the vehicle file and returns its path; if it
        raises, no test is created. With `quota`, QuotaExceededError (and no test) when its key would
        have more waiting or running tests than it allows (service.store.quota)."""
        with self.db.transaction() as session:
            row = ScheduleRow(
                lane=self.lane,
                bench=bench,
                vehicle_file="",
                sweep_settings=sweep_settings,
                job_options=job_options,
                run_at=run_at,
                status=ScheduleStatus.WAITING.value,
                created_by=created_by,
            )
            session.add(row)
            session.flush()
            if quota is not None:
                count = select(func.count()).select_from(ScheduleRow)
                mine = count.where(
                    ScheduleRow.created_by == quota.key_id, ScheduleRow.status.in_(UNFINISHED_TESTS)
                )
                enforce(session, quota, mine, "scheduled tests waiting or running")
            row.vehicle_file = str(place(row.id))
            session.flush()
            return ScheduleRecord.of(row)

    def get(self, test_id: int) -> ScheduleRecord | None:
        with self.db.sessions() as session:
            row = session.get(ScheduleRow, test_id)
            return ScheduleRecord.of(row) if row is not None else None

    def list_tests(
        self,
        *,
        status: ScheduleStatus | None = None,
        lane: str | None = None,
        limit: int = 50,
        offset: int = 0,
    ) -> tuple[list[ScheduleRecord], int]:
        """Newest first, and the total count that matches."""
        query = select(ScheduleRow)
        count = select(func.count()).select_from(ScheduleRow)
        if lane is not None:
            query, count = query.where(ScheduleRow.lane == lane), count.where(ScheduleRow.lane == lane)
        if status is not None:
            query = query.where(ScheduleRow.status == status.value)
            count = count.where(ScheduleRow.status == status.value)
        with self.db.sessions() as session:
            rows = session.scalars(query.order_by(ScheduleRow.id.desc()).limit(limit).offset(offset)).all()
            return [ScheduleRecord.of(r) for r in rows], int(session.scalar(count) or 0)

    def running(self, bench: str) -> ScheduleRecord | None:
        """The test this lane's bench is running, if any (at most one: `claim_next` sees to it)."""
        with self.db.sessions() as session:
            row = session.scalars(
                select(ScheduleRow)
                .where(
                    ScheduleRow.lane == self.lane,
                    ScheduleRow.bench == bench,
                    ScheduleRow.status == ScheduleStatus.RUNNING.value,
                )
                .order_by(ScheduleRow.id)
                .limit(1)
            ).first()
            return ScheduleRecord.of(row) if row is not None else None

    def claim_next(self, bench: str, now: datetime) -> ScheduleRecord | None:
        """The next due test of this lane's bench, marked running (another lane's tests are its own
        scheduler's); None when none is due or one already runs.
        Due: `run_at` has come, or it has none. Order: by when each became due (its `run_at`, else when
        it was submitted), then by id."""
        due_since = func.coalesce(ScheduleRow.run_at, ScheduleRow.created_at)
        with self.db.transaction() as session:
            busy = session.scalar(
                select(func.count())
                .select_from(ScheduleRow)
                .where(
                    ScheduleRow.lane == self.lane,
                    ScheduleRow.bench == bench,
                    ScheduleRow.status == ScheduleStatus.RUNNING.value,
                )
            )
            if busy:
                return None
            candidates = session.scalars(
                select(ScheduleRow.id)
                .where(
                    ScheduleRow.lane == self.lane,
                    ScheduleRow.bench == bench,
                    ScheduleRow.status == ScheduleStatus.WAITING.value,
                    (ScheduleRow.run_at.is_(None)) | (ScheduleRow.run_at <= now),
                )
                .order_by(due_since, ScheduleRow.id)
                .limit(1)
            ).all()
            if not candidates:
                return None
            taken = session.execute(
                update(ScheduleRow)
                .where(ScheduleRow.id == candidates[0], ScheduleRow.status == ScheduleStatus.WAITING.value)
                .values(status=ScheduleStatus.RUNNING.value, started_at=utcnow())
            )
            if taken.rowcount != 1:
                return None
            row = session.get(ScheduleRow, candidates[0])
            assert row is not None
            session.refresh(row)
            return ScheduleRecord.of(row)

    def _transition(self, test_id: int, from_status: tuple[ScheduleStatus, ...], **values: Any) -> bool:
        with self.db.transaction() as session:
            done = session.execute(
                update(ScheduleRow)
                .where(ScheduleRow.id == test_id, ScheduleRow.status.in_([s.value for s in from_status]))
                .values(**values)
            )
            return done.rowcount == 1

    def release(self, test_id: int) -> bool:
        """running -> waiting: the bench was taken between the claim and the start (an operator's sweep);
        the test waits for the next free moment."""
        return self._transition(
            test_id, (ScheduleStatus.RUNNING,), status=ScheduleStatus.WAITING.value, started_at=None
        )

    def attach_sweep(self, test_id: int, sweep_id: int) -> bool:
        return self._transition(test_id, (ScheduleStatus.RUNNING,), sweep_id=sweep_id)

    def finish(
        self, test_id: int, status: ScheduleStatus, *, reason: str | None = None, job_id: int | None = None
    ) -> bool:
        """running -> done or failed (once: a later call changes nothing)."""
        if status not in (ScheduleStatus.DONE, ScheduleStatus.FAILED):
            raise ValueError(f"{status.value} is not how a running test ends")
        return self._transition(
            test_id,
            (ScheduleStatus.RUNNING,),
            status=status.value,
            reason=reason,
            job_id=job_id,
            finished_at=utcnow(),
        )

    def cancel(self, test_id: int) -> bool:
        """waiting -> cancelled; False when it has begun or ended."""
        return self._transition(
            test_id,
            (ScheduleStatus.WAITING,),
            status=ScheduleStatus.CANCELLED.value,
            reason="cancelled before it began",
            finished_at=utcnow(),
        )
