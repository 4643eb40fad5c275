"""The database connection: an SQLAlchemy engine and short-lived sessions.

SQLite by default (a file in the data directory: embedded, no server to install), opened in WAL mode so
that readers never wait for the writer; any other SQLAlchemy URL (e.g. postgresql+psycopg://...) works
unchanged with the same models. The schema is Alembic's (service.store.schema): `upgrade_schema` creates
it in a new database, upgrades an older one, and refuses one a newer shockbench wrote.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sqlalchemy import create_engine, event
from sqlalchemy.engine import URL, Engine, make_url
from sqlalchemy.exc import ArgumentError, NoSuchModuleError, SQLAlchemyError
from sqlalchemy.orm import Session, sessionmaker

from estimator.errors import UserError
from service.extras import extra_needed

DATABASE_FILE = "shockbench.sqlite3"
CONNECT_TIMEOUT_S = 10
"""A PostgreSQL server that does not answer a connection within this long counts as unreachable."""
POSTGRES_LIVENESS = {
    "keepalives": 1,
    "keepalives_idle": 10,
    "keepalives_interval": 5,
    "keepalives_count": 3,
    "tcp_user_timeout": 30_000,
}
"""libpq's TCP keepalives (s) and unacknowledged-data limit (ms): a server cut off without closing the
connection (network down, not stopped) is noticed in about half a minute instead of the system's hours,
so that a lane's sync (service.api.central_sync) reports it away rather than waiting on it."""


class DatabaseError(UserError, ValueError):
    """The database URL is unusable or the database cannot be opened; one line, no password."""


def default_database_url(data_dir: Path) -> str:
    return f"sqlite:///{(Path(data_dir) / DATABASE_FILE).resolve()}"


def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.close()


class Database:
    """Engine plus session factory. Sessions are short (one unit of work each) and may be used from any
    thread; the API calls them from worker threads, never holding one across an await."""

    def __init__(self, url: str, *, outbox: bool = False) -> None:
        """outbox: this is a lane's local store; its stores queue every finished sweep and job for the
        central database (service.store.outbox, service.store.sync)."""
        self.outbox = outbox
        try:
            parsed: URL = make_url(url)
        except ArgumentError:
            raise DatabaseError(f"database URL {url!r} is not a valid SQLAlchemy URL") from None
        self.url = parsed
        kwargs: dict[str, Any] = {}
        if parsed.get_backend_name() == "sqlite":
            if parsed.database and parsed.database != ":memory:":
                Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
            kwargs["connect_args"] = {"check_same_thread": False, "timeout": 30}
        else:
            # a server that went away and came back: stale pooled connections are replaced, not used
            kwargs["pool_pre_ping"] = True
            if parsed.get_backend_name() == "postgresql":
                defaults = {**POSTGRES_LIVENESS, "connect_timeout": CONNECT_TIMEOUT_S}
                kwargs["connect_args"] = {
                    k: v for k, v in defaults.items() if k not in parsed.query
                }  # URL wins
        try:
            # PostgreSQL's driver is the [postgres] extra: SQLAlchemy imports it here, and its absence is one
            # line naming the extra (service.extras), not "No module named 'psycopg'"
            with extra_needed("postgres", f"database {self.safe_url}", DatabaseError):
                self.engine: Engine = create_engine(parsed, **kwargs)
        except (NoSuchModuleError, ModuleNotFoundError, ArgumentError) as exc:
            raise DatabaseError(f"database {self.safe_url}: {str(exc).splitlines()[0]}") from None
        if parsed.get_backend_name() == "sqlite":
            event.listen(self.engine, "connect", _sqlite_pragmas)
        self.sessions = sessionmaker(self.engine, expire_on_commit=False)

    @property
    def safe_url(self) -> str:
        return self.url.render_as_string(hide_password=True)

    def upgrade_schema(self) -> tuple[str | None, str]:
        """Create or upgrade the tables to the newest schema revision; (revision before, after). A
        DatabaseError (one line) when the server cannot be reached, SchemaError when the database is
        newer than this shockbench."""
        from service.store.schema import upgrade

        try:
            return upgrade(self.engine)
        except SQLAlchemyError as exc:
            raise DatabaseError(f"database {self.safe_url}: {str(exc).splitlines()[0]}") from None

    def require_newest_schema(self) -> str:
        """For a command that only reads: the schema revision when it is the newest this shockbench knows;
        else SchemaError (empty, older: `shockbench db upgrade`, newer), DatabaseError when unreachable."""
        from service.store.schema import require_newest

        try:
            return require_newest(self.engine)
        except SQLAlchemyError as exc:
            raise DatabaseError(f"database {self.safe_url}: {str(exc).splitlines()[0]}") from None

    @contextmanager
    def transaction(self) -> Iterator[Session]:
        """A session in a transaction: committed on success, rolled back on error."""
        with self.sessions.begin() as session:
            yield session

    def dispose(self) -> None:
        self.engine.dispose()
