"""Alembic's environment for shockbench: migrations run on the connection service.store.schema hands it
(no alembic.ini, no URL here), in one transaction per upgrade where the back end allows it."""

from __future__ import annotations

from alembic import context

from service.store.models import Base

connection = context.config.attributes["connection"]
context.configure(
    connection=connection,
    target_metadata=Base.metadata,
    render_as_batch=connection.dialect.name == "sqlite",  # SQLite alters tables by copying them
)
with context.begin_transaction():
    context.run_migrations()
