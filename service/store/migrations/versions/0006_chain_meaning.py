"""A chain that covers what a result means (service.store.result_chain, link format 2): the recording hashes
of jobs and sweeps, the links' format (`link_version`: the links written before stay format 1 and keep
verifying by it), the digests of the fields a format 2 link covers, each link's place in its lane's chain
(`sequence`, numbered here for the links there are), and the central database's checkpoints of the lanes'
chain heads (service.store.chain_anchor).

The recordings of rows stored before are not hashed here: their links (format 1) do not cover them. Columns
are added with plain ADD COLUMN (no batch copy on SQLite: other tables' foreign keys point at jobs and
sweeps); tables are written out here, not taken from the models, so that this revision stays what it is.

Revision ID: 0006
Revises: 0005
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from service.store.models import UTCDateTime

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

LINKS = sa.table(
    "result_chain",
    sa.column("id", sa.Integer),
    sa.column("lane", sa.String),
    sa.column("sequence", sa.Integer),
)


def upgrade() -> None:
    for table in ("sweeps", "jobs"):
        op.add_column(table, sa.Column("recording_sha256", sa.String(64)))
    op.add_column("result_chain", sa.Column("link_version", sa.Integer, nullable=False, server_default="1"))
    op.add_column("result_chain", sa.Column("covered", sa.JSON))
    op.add_column("result_chain", sa.Column("sequence", sa.Integer))
    number_links()
    op.create_index("uq_result_chain_lane_sequence", "result_chain", ["lane", "sequence"], unique=True)
    op.create_table(
        "chain_checkpoints",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("lane", sa.String(100), nullable=False),
        sa.Column("sequence", sa.Integer, nullable=False),
        sa.Column("job_id", sa.Integer, nullable=False),
        sa.Column("hash", sa.String(64), nullable=False),
        sa.Column("checkpointed_at", UTCDateTime(), nullable=False),
        sqlite_autoincrement=True,
    )
    op.create_index(
        "uq_chain_checkpoints_lane_sequence", "chain_checkpoints", ["lane", "sequence"], unique=True
    )


def number_links() -> None:
    """Each existing link's place in its lane's chain: 1, 2, ... in the order of ids (the chain's order)."""
    connection = op.get_bind()
    rows = connection.execute(sa.select(LINKS.c.id, LINKS.c.lane).order_by(LINKS.c.lane, LINKS.c.id)).all()
    counts: dict[str, int] = {}
    numbers = []
    for link_id, lane in rows:
        counts[lane] = counts.get(lane, 0) + 1
        numbers.append({"link_id": link_id, "number": counts[lane]})
    if numbers:  # one statement, executed for every link (executemany)
        fill = (
            LINKS.update()
            .where(LINKS.c.id == sa.bindparam("link_id"))
            .values(sequence=sa.bindparam("number"))
        )
        connection.execute(fill, numbers)
