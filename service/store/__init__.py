"""Persistence of jobs, sweeps and schedules through SQLAlchemy: SQLite by default, any SQLAlchemy URL
(PostgreSQL) unchanged. Recordings stay in their files; the database holds their paths."""

from service.store.database import Database, default_database_url
from service.store.jobs import JobRecord, JobStore
from service.store.models import JobKind, JobStatus, ScheduleStatus, SweepStatus

__all__ = [
    "Database",
    "JobKind",
    "JobRecord",
    "JobStatus",
    "JobStore",
    "ScheduleStatus",
    "SweepStatus",
    "default_database_url",
]
