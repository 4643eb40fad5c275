"""Lanes: every sweep, job and scheduled test carries the lane (the `serve --lane` instance) it belongs to.

Rows written before lanes existed get the empty lane "" (unknown); lists filter by lane, and a lane's
scheduler claims only its own tests.

Revision ID: 0002
Revises: 0001
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

TABLES = ("sweeps", "jobs", "schedules")


def upgrade() -> None:
    for table in TABLES:
        with op.batch_alter_table(table) as batch:
            batch.add_column(sa.Column("lane", sa.String(100), nullable=False, server_default=""))
            batch.create_index(f"ix_{table}_lane", ["lane"])
