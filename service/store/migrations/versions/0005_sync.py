"""A lane's local store synced to a central database (service.store.sync): a global identity (`uid`, a
UUID) on sweeps and jobs, the id a synced job had in its lane (`origin_id`, which its chain link hashes),
and the outbox of rows waiting to be pushed. Rows stored before this revision get their uid here.

Revision ID: 0005
Revises: 0004
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from service.store.models import UTCDateTime, new_uid

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    connection = op.get_bind()
    for table in ("sweeps", "jobs"):
        # plain ADD COLUMN (no batch copy on SQLite: other tables' foreign keys point at both)
        op.add_column(table, sa.Column("uid", sa.String(36)))
        rows = sa.table(table, sa.column("id", sa.Integer), sa.column("uid", sa.String))
        ids = connection.execute(sa.select(rows.c.id)).scalars().all()
        if ids:  # one statement, executed for every row (executemany)
            fill = rows.update().where(rows.c.id == sa.bindparam("row_id")).values(uid=sa.bindparam("new"))
            connection.execute(fill, [{"row_id": row_id, "new": new_uid()} for row_id in ids])
        op.create_index(f"uq_{table}_uid", table, ["uid"], unique=True)
    op.add_column("jobs", sa.Column("origin_id", sa.Integer))
    op.create_table(
        "sync_outbox",
        sa.Column("seq", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("row_id", sa.Integer, nullable=False),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sqlite_autoincrement=True,
    )
