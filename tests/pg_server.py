"""A real PostgreSQL server for the tests, started from Debian's binaries in a temporary folder.

Why not pytest-postgresql or testing.postgresql: both run initdb and pg_ctl as the current user, and CI runs
as root, which initdb refuses. Here, as root, the cluster belongs to the `postgres` system user (which
Debian's package creates) and the binaries run as that user through runuser; otherwise as ourselves. The
server listens on a free loopback port with trust authentication, fsync off (a test database needs no
durability), and is stopped (immediate mode) at the end of the session.

`PostgresServer.new_database()` gives each test its own empty database on the one server, so tests
never see each other's rows and the server starts only once per session.
"""

from __future__ import annotations

import itertools
import os
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path

import psycopg

CI_NEEDS_POSTGRES = "CI"
"""When this environment variable is set, a missing PostgreSQL fails the tests instead of skipping them."""


def find_bindir() -> Path | None:
    """The folder of Debian's pg_ctl and initdb (the newest version installed), or None."""
    found = sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl"), key=lambda p: int(p.parts[-3]))
    if found:
        return found[-1].parent
    pg_ctl = shutil.which("pg_ctl")
    return Path(pg_ctl).parent if pg_ctl else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


class PostgresServer:
    """`with PostgresServer() as server: url = server.new_database()`."""

    def __init__(self, bindir: Path) -> None:
        self.bindir = bindir
        self.port = _free_port()
        self.folder = Path(tempfile.mkdtemp(prefix="shockbench-pg-"))
        self.data = self.folder / "data"
        self._names = itertools.count(1)
        self._as_root = os.geteuid() == 0

    def _run(self, *args: str) -> None:
        command = [str(self.bindir / args[0]), *args[1:]]
        if self._as_root:
            command = ["runuser", "-u", "postgres", "--", *command]
        done = subprocess.run(command, capture_output=True, text=True, timeout=120)
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(args[:2])} failed: {(done.stderr or done.stdout).strip()}")

    def __enter__(self) -> PostgresServer:
        if self._as_root:
            shutil.chown(self.folder, "postgres", "postgres")
        self._run("initdb", "-D", str(self.data), "-U", "postgres", "-A", "trust", "-E", "UTF8", "--no-sync")
        self.start()
        return self

    def start(self) -> None:
        """Start the server (again, after `stop`) on its port; returns once it accepts connections."""
        options = f"-p {self.port} -k {self.folder} -c listen_addresses=127.0.0.1 -c fsync=off"
        self._run(
            "pg_ctl", "-D", str(self.data), "-o", options, "-l", str(self.folder / "log"), "-w", "start"
        )

    def stop(self) -> None:
        """Stop the server at once (immediate mode: open connections are cut, as by a crash or a network
        failure); returns once it is down. Its databases come back with `start`."""
        self._run("pg_ctl", "-D", str(self.data), "-m", "immediate", "-w", "stop")

    def running(self) -> bool:
        """Whether the server runs now (pg_ctl status: 0 running, 3 not)."""
        try:
            self._run("pg_ctl", "-D", str(self.data), "status")
        except RuntimeError:
            return False
        return True

    def _dsn(self, database: str = "postgres") -> str:
        return f"host=127.0.0.1 port={self.port} user=postgres dbname={database} connect_timeout=5"

    def __exit__(self, *_exc: object) -> None:
        try:
            if self.running():
                self.stop()
        finally:
            shutil.rmtree(self.folder, ignore_errors=True)

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{database}"

    def new_database(self) -> str:
        """A new, empty database on this server; its SQLAlchemy URL (psycopg 3)."""
        name = f"test_{next(self._names)}"
        with psycopg.connect(self._dsn(), autocommit=True) as c:
            c.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)
