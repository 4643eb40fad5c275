"""The outbox of a lane's local store: what it must still push to the central database (service.store.sync).

A sweep or job that reaches its final state is queued here in the same transaction that writes that state
(the stores call `queue_finished`), so nothing finished can be left out, and the order of `seq` is the
order things finished in: the order of the lane's result chain. Only a database opened with `outbox=True`
(the lane's local store) queues anything.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from service.store.database import Database
from service.store.models import SyncOutboxRow, utcnow

SWEEP = "sweep"
JOB = "job"


def queue_finished(database: Database, session: Session, kind: str, row_ids: Iterable[int]) -> None:
    """In `session`'s transaction: queue the finished rows for the central database (when `database` is a
    lane's local store; elsewhere nothing)."""
    if not database.outbox:
        return
    now = utcnow()
    session.add_all(SyncOutboxRow(kind=kind, row_id=row_id, created_at=now) for row_id in row_ids)


@dataclass(frozen=True)
class Backlog:
    count: int
    """Entries not yet pushed."""
    oldest: datetime | None
    """When the oldest of them was queued (UTC); None when there are none."""


def backlog(database: Database) -> Backlog:
    with database.sessions() as session:
        count, oldest = session.execute(select(func.count(), func.min(SyncOutboxRow.created_at))).one()
    return Backlog(int(count or 0), oldest)
