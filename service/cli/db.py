"""`shockbench db upgrade`: bring a database's schema to this shockbench's newest revision (Alembic,
service.store.schema), keeping every row. `serve` does the same at start; this command lets an operator
upgrade a shared PostgreSQL once, before the lanes' services are updated."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from service.cli.errors import CliError

if TYPE_CHECKING:
    from service.store.database import Database


def add_database_arguments(parser: argparse.ArgumentParser) -> None:
    """--database URL and --data DIR: where a command that reads the service's database finds it."""
    parser.add_argument("--database", default=None, help="SQLAlchemy URL (default: SQLite in --data)")
    parser.add_argument(
        "--data", default="shockbench-data", help="data directory (default ./shockbench-data)"
    )


def open_database(url: str | None, data: str) -> Database:
    """The service's database for a command that reads it (`history`, `verify`): `url`, else the SQLite
    file in the data directory `data`. One line (exit 2) when there is no database there, or its schema is
    not this shockbench's newest (service.store.schema.require_newest). The caller disposes of it."""
    from service.store.database import DATABASE_FILE, Database, default_database_url

    if url is None and not (Path(data) / DATABASE_FILE).is_file():
        raise CliError(f"no database in {data!r} (no {DATABASE_FILE}); name one with --database or --data")
    database = Database(url or default_database_url(Path(data).resolve()))
    try:
        database.require_newest_schema()
    except BaseException:
        database.dispose()
        raise
    return database


def run_db_upgrade(args: argparse.Namespace) -> int:
    from service.store.database import Database, default_database_url
    from service.store.schema import head_revision

    database = Database(args.database or default_database_url(Path(args.data).resolve()))
    try:
        before, after = database.upgrade_schema()
    finally:
        database.dispose()
    if before == after:
        print(f"database {database.safe_url}: already at schema revision {after} (the newest)")
    else:
        print(f"database {database.safe_url}: schema {before or 'empty'} -> {after}")
    assert after == head_revision()
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "db",
        help="database schema: upgrade",
        description="The service's database. `db upgrade` brings its schema to the newest revision this "
        "shockbench knows, keeping every row; a database a newer shockbench wrote is refused.",
    )
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    upgrade = actions.add_parser("upgrade", help="create or upgrade the schema to the newest revision")
    add_database_arguments(upgrade)
    upgrade.set_defaults(handler=run_db_upgrade)
