"""Sweeps in the database: requested -> running -> complete / failed / aborted, read back.

Like service.store.jobs: every state change is one conditional UPDATE, each call opens its own short
session, so the methods are safe from any thread (the API's worker threads, and a sweep's own thread when
it ends). SweepRecord is a detached snapshot of a row.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from sqlalchemy import ColumnElement, func, select, update

from service.store.database import Database
from service.store.models import SweepRow, SweepStatus, utcnow
from service.store.outbox import SWEEP, queue_finished
from service.store.recordings import store_sweep_recording

RESTART_REASON = "service restarted while the sweep ran"
UNFINISHED = (SweepStatus.REQUESTED, SweepStatus.RUNNING)


def _file_bytes(path: str | None) -> bytes | None:
    """The recording file's bytes; None when the sweep left no file (or it cannot be read)."""
    if not path or not Path(path).is_file():
        return None
    try:
        return Path(path).read_bytes()
    except OSError:
        return None


def finished(status: SweepStatus) -> bool:
    return status not in UNFINISHED


def of_vehicle(vehicle_id: str) -> ColumnElement[bool]:
    """The condition "the sweep tested this vehicle": the `vehicle_id` stored in its settings, compared
    without regard to case (on SQLite and PostgreSQL alike)."""
    return func.lower(SweepRow.settings["vehicle_id"].as_string()) == vehicle_id.lower()


@dataclass(frozen=True)
class SweepRecord:
    id: int
    lane: str
    """The lane it belongs to ("" for rows from before lanes)."""
    bench: str
    status: SweepStatus
    settings: dict[str, Any]
    vehicle_file: str | None
    """Path of the vehicle file saved beside the recording."""
    recording_path: str | None
    complete: bool
    reason: str | None
    operator: str | None
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None

    @property
    def finished(self) -> bool:
        return finished(self.status)

    @classmethod
    def of(cls, row: SweepRow) -> SweepRecord:
        return cls(
            id=row.id,
            lane=row.lane,
            bench=row.bench,
            status=SweepStatus(row.status),
            settings=dict(row.settings or {}),
            vehicle_file=row.vehicle_file,
            recording_path=row.recording_path,
            complete=bool(row.complete),
            reason=row.reason,
            operator=row.operator,
            created_at=row.created_at,
            started_at=row.started_at,
            finished_at=row.finished_at,
        )


class SweepStore:
    def __init__(self, database: Database, lane: str = "") -> None:
        """lane: stamped on every row this store creates (the service's `--lane`)."""
        self.db = database
        self.lane = lane

    def create(
        self,
        bench: str,
        settings: dict[str, Any],
        place: Callable[[int], tuple[Path, Path]],
        *,
        operator: str | None = None,
    ) -> SweepRecord:
        """Insert a requested sweep. `place(sweep_id)` saves the vehicle file and says (recording path,
        vehicle file path); if it raises, no sweep is created."""
        with self.db.transaction() as session:
            row = SweepRow(
                lane=self.lane,
                bench=bench,
                status=SweepStatus.REQUESTED.value,
                settings=settings,
                operator=operator,
            )
            session.add(row)
            session.flush()
            recording, vehicle = place(row.id)
            row.recording_path, row.vehicle_file = str(recording), str(vehicle)
            session.flush()
            return SweepRecord.of(row)

    def get(self, sweep_id: int) -> SweepRecord | None:
        with self.db.sessions() as session:
            row = session.get(SweepRow, sweep_id)
            return SweepRecord.of(row) if row is not None else None

    def list_sweeps(
        self,
        *,
        status: SweepStatus | None = None,
        vehicle_id: str | None = None,
        lane: str | None = None,
        limit: int = 50,
        offset: int = 0,
    ) -> tuple[list[SweepRecord], int]:
        """Newest first, and the total count that matches. vehicle_id: only the tests of that vehicle (the
        `vehicle_id` stored in the settings), compared without regard to case."""
        query = select(SweepRow)
        count = select(func.count()).select_from(SweepRow)
        if status is not None:
            query = query.where(SweepRow.status == status.value)
            count = count.where(SweepRow.status == status.value)
        if lane is not None:
            query, count = query.where(SweepRow.lane == lane), count.where(SweepRow.lane == lane)
        if vehicle_id is not None:
            same = of_vehicle(vehicle_id)
            query, count = query.where(same), count.where(same)
        with self.db.sessions() as session:
            rows = session.scalars(query.order_by(SweepRow.id.desc()).limit(limit).offset(offset)).all()
            return [SweepRecord.of(r) for r in rows], int(session.scalar(count) or 0)

    def _transition(
        self,
        sweep_id: int,
        from_status: tuple[SweepStatus, ...],
        recording: bytes | None = None,
        **values: Any,
    ) -> bool:
        """One conditional UPDATE; when it ended the sweep, the sweep queued for the central database and
        `recording` (its file's bytes) stored with it, in the same transaction."""
        with self.db.transaction() as session:
            done = session.execute(
                update(SweepRow)
                .where(SweepRow.id == sweep_id, SweepRow.status.in_([s.value for s in from_status]))
                .values(**values)
            )
            if done.rowcount == 1 and finished(SweepStatus(values.get("status", SweepStatus.RUNNING))):
                if recording is not None:
                    row = session.get(SweepRow, sweep_id)
                    assert row is not None
                    store_sweep_recording(session, row, recording)
                queue_finished(self.db, session, SWEEP, [sweep_id])
            return done.rowcount == 1

    def mark_running(self, sweep_id: int) -> bool:
        """requested -> running; False when the sweep has already ended (a very short one)."""
        return self._transition(
            sweep_id, (SweepStatus.REQUESTED,), status=SweepStatus.RUNNING.value, started_at=utcnow()
        )

    def finish(self, sweep_id: int, status: SweepStatus, *, complete: bool, reason: str | None) -> bool:
        """requested/running -> complete, failed or aborted (once: a later call changes nothing), with the
        sha256 of its recording file as it is now (the chain links of the results on it cover it), and the
        file's bytes with its vehicle file's text kept in the database (service.store.recordings)."""
        if not finished(status):
            raise ValueError(f"{status.value} is not a final sweep status")
        with self.db.sessions() as session:
            path = session.scalar(select(SweepRow.recording_path).where(SweepRow.id == sweep_id))
        content = _file_bytes(path)
        return self._transition(
            sweep_id,
            UNFINISHED,
            content,
            status=status.value,
            complete=complete,
            reason=reason,
            finished_at=utcnow(),
            recording_sha256=hashlib.sha256(content).hexdigest() if content is not None else None,
        )

    def recover_interrupted(self, reason: str = RESTART_REASON) -> list[int]:
        """At start-up: sweeps left requested or running by a crash or a kill are marked failed."""
        with self.db.transaction() as session:
            ids = list(
                session.scalars(
                    select(SweepRow.id).where(SweepRow.status.in_([s.value for s in UNFINISHED]))
                ).all()
            )
            if ids:
                session.execute(
                    update(SweepRow)
                    .where(SweepRow.id.in_(ids))
                    .values(status=SweepStatus.FAILED.value, reason=reason, finished_at=utcnow())
                )
                queue_finished(self.db, session, SWEEP, ids)
            return ids
