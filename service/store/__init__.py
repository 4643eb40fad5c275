"""Persistence of jobs, sweeps and schedules through SQLAlchemy: SQLite by default, any SQLAlchemy URL
(PostgreSQL) unchanged. A sweep's recording is written to its file and kept in the database too, with the
archive's imported recordings and the re-analysis runs (service.store.recordings, reanalysis_runs).

Must not import service.api, service.cli, service.jobs nor simulators: the store is below every user of it."""

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
