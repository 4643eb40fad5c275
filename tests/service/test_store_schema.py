"""Schema migrations (Alembic) on SQLite and a real PostgreSQL server: a new database gets the models'
exact schema; a database written by the previous schema is upgraded without losing a row; one written by
a newer shockbench is refused in one line."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext

from service.store.database import Database
from service.store.models import Base
from service.store.schema import BASELINE, SchemaError, head_revision, upgrade


def test_a_new_database_gets_exactly_the_models_schema(database_url: str) -> None:
    database = Database(database_url)
    try:
        assert database.upgrade_schema() == (None, head_revision())
        with database.engine.connect() as connection:
            differences = compare_metadata(MigrationContext.configure(connection), Base.metadata)
        assert differences == []
        assert database.upgrade_schema() == (head_revision(), head_revision())  # idempotent
    finally:
        database.dispose()


def test_a_database_of_the_previous_schema_keeps_every_row(database_url: str) -> None:
    database = Database(database_url)
    now = datetime(2026, 11, 1, 9, 30, tzinfo=UTC)
    try:
        upgrade(database.engine, to=BASELINE)
        with database.engine.begin() as c:  # rows as the previous shockbench wrote them
            c.execute(
                sa.text(
                    "INSERT INTO sweeps (bench, status, settings, complete, created_at) "
                    "VALUES ('lane bench', 'complete', '{\"vehicle_id\": \"AB-12\"}', true, :t)"
                ),
                {"t": now},
            )
            c.execute(
                sa.text(
                    "INSERT INTO jobs (kind, status, options, input_source, recording_path, vehicle_path, "
                    "sweep_id, output_dir, result, artefacts, created_at) VALUES ('identify', 'succeeded', "
                    "'{}', 'sweep', 'r.h5', 'v.toml', 1, 'out', '{\"gap_m\": 1e-05}', '{}', :t)"
                ),
                {"t": now},
            )
            c.execute(
                sa.text(
                    "INSERT INTO schedules (bench, vehicle_file, sweep_settings, job_options, status, "
                    "created_at) VALUES ('lane bench', 'v.toml', '{}', '{}', 'waiting', :t)"
                ),
                {"t": now},
            )
        before, after = database.upgrade_schema()
        assert (before, after) == (BASELINE, head_revision())
        with database.engine.connect() as c:
            sweep = c.execute(sa.text("SELECT bench, lane, settings FROM sweeps")).one()
            job = c.execute(sa.text("SELECT sweep_id, result, lane FROM jobs")).one()
            schedule = c.execute(sa.text("SELECT status, lane FROM schedules")).one()
        assert sweep.bench == "lane bench" and sweep.lane == "" and "AB-12" in str(sweep.settings)
        assert job.sweep_id == 1 and "1e-05" in str(job.result) and job.lane == ""
        assert schedule.status == "waiting" and schedule.lane == ""
    finally:
        database.dispose()


def test_a_database_from_before_migrations_is_taken_as_the_baseline(database_url: str) -> None:
    database = Database(database_url)
    try:
        upgrade(database.engine, to=BASELINE)
        with database.engine.begin() as c:
            c.execute(sa.text("DROP TABLE alembic_version"))  # as create_all left it
        assert database.upgrade_schema() == (BASELINE, head_revision())
    finally:
        database.dispose()


def test_a_newer_schema_is_refused_in_one_line(database_url: str) -> None:
    database = Database(database_url)
    try:
        database.upgrade_schema()
        with database.engine.begin() as c:
            c.execute(sa.text("UPDATE alembic_version SET version_num = '9999'"))
        with pytest.raises(SchemaError) as refused:
            database.upgrade_schema()
        assert str(refused.value).count("\n") == 0
        assert "9999 is newer than this shockbench knows" in str(refused.value)
    finally:
        database.dispose()
