"""Shared test fixtures: simulated recordings (made once per session) and the hit-rate report."""

from __future__ import annotations

import os
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path

import pytest
from pg_server import CI_NEEDS_POSTGRES, PostgresServer, find_bindir

# One BLAS thread, as every `shockbench` process has it: importing the CLI package sets it before numpy is
# first imported (service/cli/__init__.py says why); tests that run a service worker or simulated devices
# beside the estimator would otherwise oversubscribe the 2 cores.
import service.cli  # noqa: F401
from service.store.database import Database

HIT_RATES: dict[str, list[tuple[str, bool]]] = defaultdict(list)


def report_case(experiment: str, case: str, hit: bool) -> None:
    """Record one randomly drawn case of an accuracy experiment; the summary prints the hit rate."""
    HIT_RATES[experiment].append((case, hit))


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if not HIT_RATES:
        return
    terminalreporter.section("accuracy experiments (random cases, fixed seeds)")
    for experiment, cases in HIT_RATES.items():
        hits = sum(hit for _, hit in cases)
        terminalreporter.write_line(f"{experiment}: {hits}/{len(cases)} hit")
        for case, hit in cases:
            terminalreporter.write_line(f"    {'hit ' if hit else 'MISS'} {case}")


@pytest.fixture
def hit_rate():
    """report(experiment, case, hit): record a random case of an accuracy experiment for the summary."""
    return report_case


def postgres_bindir() -> Path:
    """Debian's PostgreSQL binaries; the test is skipped without them, except in CI (the environment
    variable CI set), where .ci/run installs them and a missing one fails."""
    bindir = find_bindir()
    if bindir is None:
        if os.environ.get(CI_NEEDS_POSTGRES):
            pytest.fail("PostgreSQL binaries (Debian's postgresql) not found, and CI needs them")
        pytest.skip("PostgreSQL binaries not found (apt-get install postgresql)")
    return bindir


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    """A real PostgreSQL server for the session (tests/pg_server.py; see postgres_bindir)."""
    with PostgresServer(postgres_bindir()) as server:
        yield server


@pytest.fixture
def own_postgres() -> Iterator[PostgresServer]:
    """A real PostgreSQL server of this test's own, which it may stop and start (PostgresServer.stop,
    .start) without disturbing the session's."""
    with PostgresServer(postgres_bindir()) as server:
        yield server


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """An empty database of each kind the service supports: SQLite in tmp_path, and a fresh database on
    the session's PostgreSQL server."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'shockbench.sqlite3'}"
    server: PostgresServer = request.getfixturevalue("postgres")
    return server.new_database()


@pytest.fixture
def database(database_url: str) -> Iterator[Database]:
    """`database_url` opened, its schema at the newest revision (service.store.schema)."""
    database = Database(database_url)
    database.upgrade_schema()
    yield database
    database.dispose()
