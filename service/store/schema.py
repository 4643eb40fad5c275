"""The database's schema version: Alembic migrations (service/store/migrations/versions), run in code.

- A new, empty database is brought to the newest revision by the migrations themselves.
- A database made before migrations existed (the tables, no `alembic_version`) is revision 0001: it is
  stamped so, then upgraded.
- An older revision is upgraded (`shockbench db upgrade`, and `serve` at start).
- A revision this shockbench does not know (written by a newer one) is refused with one line: an older
  program must not write into a schema it does not understand.

Why Alembic: schema changes (lanes, the job queue's lease, the result chain) must reach databases that
already hold an inspection station's results, without losing a row, on SQLite and PostgreSQL alike.
"""

from __future__ import annotations

from pathlib import Path

from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import inspect
from sqlalchemy.engine import Connection, Engine

from estimator.errors import UserError

MIGRATIONS = Path(__file__).resolve().parent / "migrations"
BASELINE = "0001"
"""The schema as `create_all` made it before migrations."""


class SchemaError(UserError, RuntimeError):
    """The database's schema cannot be used by this shockbench (one line, what to do)."""


def _config(connection: Connection | None = None) -> Config:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    if connection is not None:
        config.attributes["connection"] = connection
    return config


def head_revision() -> str:
    """The newest revision this shockbench knows."""
    head = ScriptDirectory.from_config(_config()).get_current_head()
    assert head is not None
    return head


def known_revisions() -> set[str]:
    return {script.revision for script in ScriptDirectory.from_config(_config()).walk_revisions()}


def current_revision(connection: Connection) -> str | None:
    """The database's revision: None when it is empty, BASELINE when it predates migrations."""
    revision = MigrationContext.configure(connection).get_current_revision()
    if revision is None and inspect(connection).has_table("jobs"):
        return BASELINE
    return revision


def upgrade(engine: Engine, to: str | None = None) -> tuple[str | None, str]:
    """Bring the database to revision `to` (default: the newest). Returns (revision before, after).
    SchemaError when the database's revision is unknown here (a newer shockbench wrote it)."""
    from alembic import command  # imported when needed: the CLI's --help stays light

    target = to or head_revision()
    with engine.begin() as connection:
        before = current_revision(connection)
        if before is not None and before not in known_revisions():
            raise SchemaError(
                f"database schema revision {before} is newer than this shockbench knows (newest "
                f"{head_revision()}): upgrade shockbench, or use a database of this version"
            )
        config = _config(connection)
        if before == BASELINE and MigrationContext.configure(connection).get_current_revision() is None:
            command.stamp(config, BASELINE)
        command.upgrade(config, target)
        after = current_revision(connection)
    assert after is not None
    return before, after
