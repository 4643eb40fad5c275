"""A vehicle's history in the database: every test (sweep) of that vehicle, across lanes, each with its
newest succeeded identification and that result's hash in the result chain, in one query on SQLite and
PostgreSQL alike."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import func, select

from service.store.database import Database
from service.store.jobs import JobRecord
from service.store.models import JobKind, JobRow, JobStatus, ResultChainRow, SweepRow
from service.store.sweeps import SweepRecord, of_vehicle


@dataclass(frozen=True)
class VehicleTest:
    """One test of the vehicle: its sweep, and the newest identification of it that succeeded (None when
    none did, e.g. the sweep failed or was never identified)."""

    sweep: SweepRecord
    identification: JobRecord | None
    result_hash: str | None = None
    """The identification's result hash in its lane's chain (service.store.result_chain)."""


def vehicle_tests(
    database: Database, vehicle_id: str, *, lane: str | None = None, other_than: str | None = None
) -> list[VehicleTest]:
    """Every sweep whose settings name `vehicle_id` (without regard to case), of every lane (or only of
    `lane`, or of every lane but `other_than`), newest first (by the time it was requested, then id), joined
    with its newest succeeded identify job."""
    newest = (
        select(JobRow.sweep_id.label("sweep_id"), func.max(JobRow.id).label("job_id"))
        .where(
            JobRow.kind == JobKind.IDENTIFY.value,
            JobRow.status == JobStatus.SUCCEEDED.value,
            JobRow.sweep_id.is_not(None),
        )
        .group_by(JobRow.sweep_id)
        .subquery()
    )
    query = (
        select(SweepRow, JobRow, ResultChainRow.hash)
        .where(of_vehicle(vehicle_id))
        .outerjoin(newest, newest.c.sweep_id == SweepRow.id)
        .outerjoin(JobRow, JobRow.id == newest.c.job_id)
        .outerjoin(ResultChainRow, ResultChainRow.job_id == JobRow.id)
        .order_by(SweepRow.created_at.desc(), SweepRow.id.desc())
    )
    if lane is not None:
        query = query.where(SweepRow.lane == lane)
    if other_than is not None:
        query = query.where(SweepRow.lane != other_than)
    with database.sessions() as session:
        return [
            VehicleTest(SweepRecord.of(sweep), JobRecord.of(job) if job is not None else None, digest)
            for sweep, job, digest in session.execute(query).all()
        ]
