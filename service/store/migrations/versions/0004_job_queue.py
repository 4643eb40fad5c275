"""The shared job queue: which instance runs a job (claimed_by), until when its claim holds unless renewed
(lease_until), how many times it was begun (attempts), and a cancel asked on another instance
(cancel_requested).

Revision ID: 0004
Revises: 0003
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # plain ADD COLUMNs (no batch copy of the table on SQLite: other tables' foreign keys point at jobs)
    op.add_column("jobs", sa.Column("claimed_by", sa.String(100)))
    op.add_column("jobs", sa.Column("lease_until", sa.DateTime(timezone=True)))
    op.add_column("jobs", sa.Column("attempts", sa.Integer, nullable=False, server_default="0"))
    cancel_requested = sa.Column("cancel_requested", sa.Boolean, nullable=False, server_default=sa.false())
    op.add_column("jobs", cancel_requested)
