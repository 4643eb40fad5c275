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

from collections.abc import Iterator
from contextlib import contextmanager
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


@contextmanager
def sqlite_foreign_keys_off(connection: Connection) -> Iterator[None]:
    """On SQLite, foreign keys unenforced while the migrations run, enforced again after (elsewhere, nothing).

    Alembic alters an SQLite table by copying it and dropping the original (batch mode), and SQLite refuses
    to drop a table that rows of another still reference (a result's chain link, a scheduled test's job)
    while foreign keys are enforced; the copy keeps every id, so the references hold again at the end,
    which `upgrade` checks (PRAGMA foreign_key_check) before it commits. The pragma only takes effect
    outside a transaction, hence the commits around it."""
    if connection.dialect.name != "sqlite":
        yield
        return
    connection.exec_driver_sql("PRAGMA foreign_keys=OFF")
    connection.commit()
    try:
        yield
    finally:
        connection.rollback()
        connection.exec_driver_sql("PRAGMA foreign_keys=ON")
        connection.commit()


def _check_foreign_keys(connection: Connection) -> None:
    if connection.dialect.name == "sqlite":
        broken = connection.exec_driver_sql("PRAGMA foreign_key_check").all()
        if broken:
            raise SchemaError(
                f"the migration left {len(broken)} rows of {broken[0][0]} referring to rows that do not "
                "exist; upgrade refused"
            )


def upgrade(engine: Engine, to: str | None = None) -> tuple[str | None, str]:
    """Bring the database to revision `to` (default: the newest). Returns (revision before, after).
    SchemaError when the database's revision is unknown here (a newer shockbench wrote it)."""
    from alembic import command  # imported when needed: the CLI's --help stays light

    target = to or head_revision()
    with engine.connect() as connection, sqlite_foreign_keys_off(connection), connection.begin():
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
        _check_foreign_keys(connection)
        after = current_revision(connection)
    assert after is not None
    return before, after


def require_newest(engine: Engine) -> str:
    """For a command that only reads: the database's revision when it is this shockbench's newest; else a
    SchemaError (one line) saying what to do: an empty database has nothing to read, an older one needs
    `shockbench db upgrade`, a newer one a newer shockbench."""
    head = head_revision()
    with engine.connect() as connection:
        revision = current_revision(connection)
    if revision is None:
        raise SchemaError("the database holds no shockbench tables (wrong --database or --data?)")
    if revision not in known_revisions():
        raise SchemaError(
            f"database schema revision {revision} is newer than this shockbench knows (newest {head}): "
            "upgrade shockbench"
        )
    if revision != head:
        raise SchemaError(
            f"database schema revision {revision} is older than this shockbench's ({head}): run "
            "`shockbench db upgrade` first"
        )
    return revision
