"""The result chain: every succeeded job's result carries a content hash chained to its lane's previous
result (service.store.result_chain), so that `shockbench verify` names any record altered afterwards.

The results stored before this revision are chained here, per lane in the order they finished (then by
id), so that every stored result has its link from now on. The columns are read through a table written
out here, not the models, so that this revision stays what it is when the jobs table gains columns.

Revision ID: 0003
Revises: 0002
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from service.store.models import UTCDateTime, utcnow
from service.store.result_chain import GENESIS, link_hash

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

JOBS = sa.table(
    "jobs",
    sa.column("id", sa.Integer),
    sa.column("lane", sa.String),
    sa.column("kind", sa.String),
    sa.column("status", sa.String),
    sa.column("options", sa.JSON),
    sa.column("result", sa.JSON),
    sa.column("finished_at", UTCDateTime()),  # aware UTC, as the models read it: the same hash
)


def upgrade() -> None:
    chain = op.create_table(
        "result_chain",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("lane", sa.String(100), nullable=False),
        sa.Column("job_id", sa.Integer, sa.ForeignKey("jobs.id"), nullable=False),
        sa.Column("previous_hash", sa.String(64), nullable=False),
        sa.Column("hash", sa.String(64), nullable=False),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.UniqueConstraint("job_id", name="uq_result_chain_job"),
        sa.UniqueConstraint("lane", "previous_hash", name="uq_result_chain_lane_previous"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_result_chain_lane_id", "result_chain", ["lane", "id"])
    chain_existing_results(chain)


def chain_existing_results(chain: sa.Table) -> None:
    connection = op.get_bind()
    succeeded = (
        sa.select(JOBS)
        .where(JOBS.c.status == "succeeded")
        .order_by(JOBS.c.lane, JOBS.c.finished_at, JOBS.c.id)
    )
    previous: dict[str, str] = {}
    for job in connection.execute(succeeded).all():
        before = previous.get(job.lane, GENESIS)
        digest = link_hash(before, job.id, job.lane, job.kind, job.options, job.result, job.finished_at)
        connection.execute(
            chain.insert().values(
                lane=job.lane,
                job_id=job.id,
                previous_hash=before,
                hash=digest,
                created_at=utcnow(),
            )
        )
        previous[job.lane] = digest
