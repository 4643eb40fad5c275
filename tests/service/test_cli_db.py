"""`shockbench db upgrade` and `serve` against the schema version: a new database is created, an older
one upgraded, and one written by a newer shockbench refused by serve in one line (exit 2)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import sqlalchemy as sa

from service.store.database import Database
from service.store.schema import BASELINE, head_revision, upgrade


def shockbench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "service.cli.main", *args], capture_output=True, text=True, timeout=120
    )


def test_db_upgrade_creates_then_upgrades_and_says_so(tmp_path: Path, database_url: str) -> None:
    database = Database(database_url)
    upgrade(database.engine, to=BASELINE)
    database.dispose()
    done = shockbench("db", "upgrade", "--database", database_url)
    assert done.returncode == 0, done.stderr
    assert f"schema {BASELINE} -> {head_revision()}" in done.stdout
    again = shockbench("db", "upgrade", "--database", database_url)
    assert again.returncode == 0 and "already at schema revision" in again.stdout


def test_serve_refuses_a_newer_schema_in_one_line(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'newer.sqlite3'}"
    database = Database(url)
    database.upgrade_schema()
    with database.engine.begin() as c:
        c.execute(sa.text("UPDATE alembic_version SET version_num = '9999'"))
    database.dispose()
    refused = shockbench("serve", "--database", url, "--data", str(tmp_path), "--port", "0")
    assert refused.returncode == 2
    assert refused.stderr.strip().count("\n") == 0 and "newer than this shockbench knows" in refused.stderr
    assert "Traceback" not in refused.stderr
