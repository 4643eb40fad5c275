"""The archive in the database (issue 33): recordings kept with their bytes, sha256 and vehicle text
(service.store.recordings), and re-analysis runs with one result per run, recording and analysis
(service.store.reanalysis_runs).

Only new tables: no link of the result chain changes, so every chain verifies as before. The recordings
of sweeps stored before this revision stay in their files (`shockbench archive import` can store them).
Tables are written out here, not taken from the models, so that this revision stays what it is.

Revision ID: 0007
Revises: 0006
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from service.store.models import UTCDateTime

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "recordings",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("sha256", sa.String(64), nullable=False),
        sa.Column("name", sa.Text, nullable=False),
        sa.Column("format", sa.String(8), nullable=False),
        sa.Column("compression", sa.String(8), nullable=False),
        sa.Column("size_bytes", sa.Integer, nullable=False),
        sa.Column("data", sa.LargeBinary, nullable=False),
        sa.Column("vehicle_text", sa.Text),
        sa.Column("vehicle_id", sa.String(200)),
        sa.Column("sweep_uid", sa.String(36)),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.UniqueConstraint("sha256", name="uq_recordings_sha256"),
        sqlite_autoincrement=True,
    )
    op.create_table(
        "reanalysis_runs",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("software_version", sa.String(64), nullable=False),
        sa.Column("options", sa.JSON, nullable=False),
        sa.Column("started_at", UTCDateTime(), nullable=False),
        sa.Column("finished_at", UTCDateTime()),
        sa.Column("recordings", sa.Integer, nullable=False),
        sa.Column("succeeded", sa.Integer, nullable=False),
        sa.Column("failed", sa.Integer, nullable=False),
        sqlite_autoincrement=True,
    )
    op.create_table(
        "reanalysis_results",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("run_id", sa.Integer, sa.ForeignKey("reanalysis_runs.id"), nullable=False),
        sa.Column("recording_sha256", sa.String(64), nullable=False),
        sa.Column("analysis", sa.String(16), nullable=False),
        sa.Column("result", sa.JSON),
        sa.Column("reason", sa.Text),
        sa.Column("seconds", sa.Float, nullable=False),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.UniqueConstraint("run_id", "recording_sha256", "analysis", name="uq_reanalysis_results_once"),
        sqlite_autoincrement=True,
    )
