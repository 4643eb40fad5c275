"""The schema before migrations: jobs, sweeps and scheduled tests (as `create_all` made it up to 2026-11).

A database made by an earlier shockbench (tables, no alembic_version) is this revision: service.store.schema
stamps it so, then upgrades it. The tables are written out here, not taken from the models, so that this
revision stays what it was when the models change.

Revision ID: 0001
Revises:
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

UTC_TIME = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "sweeps",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("bench", sa.String(100), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("settings", sa.JSON, nullable=False),
        sa.Column("vehicle_file", sa.Text),
        sa.Column("recording_path", sa.Text),
        sa.Column("complete", sa.Boolean, nullable=False),
        sa.Column("reason", sa.Text),
        sa.Column("operator", sa.String(64)),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.Column("started_at", UTC_TIME),
        sa.Column("finished_at", UTC_TIME),
        sqlite_autoincrement=True,
    )
    op.create_table(
        "jobs",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("options", sa.JSON, nullable=False),
        sa.Column("input_source", sa.String(16), nullable=False),
        sa.Column("recording_path", sa.Text, nullable=False),
        sa.Column("vehicle_path", sa.Text, nullable=False),
        sa.Column("sweep_id", sa.Integer, sa.ForeignKey("sweeps.id")),
        sa.Column("output_dir", sa.Text, nullable=False),
        sa.Column("result", sa.JSON),
        sa.Column("artefacts", sa.JSON, nullable=False),
        sa.Column("error", sa.Text),
        sa.Column("progress", sa.JSON),
        sa.Column("submitted_by", sa.String(64)),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.Column("started_at", UTC_TIME),
        sa.Column("finished_at", UTC_TIME),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_jobs_status", "jobs", ["status"])
    op.create_table(
        "schedules",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("bench", sa.String(100), nullable=False),
        sa.Column("vehicle_file", sa.Text, nullable=False),
        sa.Column("sweep_settings", sa.JSON, nullable=False),
        sa.Column("job_options", sa.JSON, nullable=False),
        sa.Column("run_at", UTC_TIME),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("sweep_id", sa.Integer, sa.ForeignKey("sweeps.id")),
        sa.Column("job_id", sa.Integer, sa.ForeignKey("jobs.id")),
        sa.Column("reason", sa.Text),
        sa.Column("created_by", sa.String(64)),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.Column("started_at", UTC_TIME),
        sa.Column("finished_at", UTC_TIME),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_schedules_bench_status", "schedules", ["bench", "status"])
