"""Read-only look-ups for the service's readiness probe and metrics (service.api.routes.health,
service.api.metrics): is the database answering, and how many jobs and sweeps of a lane are in each state.

Each is one short query in its own session (safe from any thread; the API calls them in a thread). The
counts list every known state, zeros included, so that a monitoring series exists before its first job.
"""

from __future__ import annotations

from sqlalchemy import func, select, text

from service.store.database import Database
from service.store.models import JobKind, JobRow, JobStatus, SweepRow, SweepStatus


def ping(database: Database) -> None:
    """`SELECT 1` on a pooled connection: returns when the database answers, raises (SQLAlchemyError)
    when it does not."""
    with database.engine.connect() as connection:
        connection.execute(text("SELECT 1"))


def job_counts(database: Database, lane: str) -> dict[tuple[str, str], int]:
    """(kind, status) -> the lane's jobs in that state, for every known kind and status (kinds the
    database holds beyond those are listed too)."""
    counts = {(kind.value, status.value): 0 for kind in JobKind for status in JobStatus}
    query = (
        select(JobRow.kind, JobRow.status, func.count())
        .where(JobRow.lane == lane)
        .group_by(JobRow.kind, JobRow.status)
    )
    with database.sessions() as session:
        for kind, status, count in session.execute(query).all():
            counts[(str(kind), str(status))] = int(count)
    return counts


def sweep_counts(database: Database, lane: str) -> dict[str, int]:
    """Status -> the lane's sweeps in that state, every known status listed."""
    counts = {status.value: 0 for status in SweepStatus}
    query = select(SweepRow.status, func.count()).where(SweepRow.lane == lane).group_by(SweepRow.status)
    with database.sessions() as session:
        for status, count in session.execute(query).all():
            counts[str(status)] = int(count)
    return counts
