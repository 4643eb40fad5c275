"""Schema migrations (Alembic) on SQLite and a real PostgreSQL server: a new database gets the models'
exact schema; a database written by the previous schema is upgraded without losing a row; one written by
a newer shockbench is refused in one line."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext

from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import Base
from service.store.result_chain import verify_chain
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
                    "sweep_id, job_id, created_at) VALUES ('lane bench', 'v.toml', '{}', '{}', 'waiting', "
                    "1, 1, :t)"
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


def test_a_lanes_database_gains_the_result_chain_with_every_row_kept_and_its_results_chained(
    database_url: str,
) -> None:
    """0002 (lanes) -> 0003 (result chain) and on: nothing is lost, and the results stored before the chain
    existed are chained per lane in the order they finished, so that `verify` holds at once. On SQLite the
    later revisions copy the jobs table, which rows of other tables refer to (chain links, a scheduled
    test): foreign keys are unenforced while the migrations run and checked at the end."""
    database = Database(database_url)
    times = [datetime(2026, 11, day, 9, 30, 0, 123456, tzinfo=UTC) for day in (1, 2, 3, 4)]
    try:
        upgrade(database.engine, to="0002")
        with database.engine.begin() as c:
            c.execute(
                sa.text(
                    "INSERT INTO sweeps (bench, lane, status, settings, complete, created_at) "
                    "VALUES ('b', 'north', 'complete', '{\"vehicle_id\": \"AB-12\"}', true, :t)"
                ),
                {"t": times[0]},
            )
            for lane, status, finished, result in (
                ("north", "succeeded", times[2], '{"gap_m": 2e-05, "inspection": {"eusama_percent": 61.5}}'),
                ("south", "succeeded", times[1], '{"gap_m": 3e-05}'),
                ("north", "succeeded", times[1], '{"gap_m": 1e-05}'),
                ("north", "failed", times[3], None),
            ):
                c.execute(
                    sa.text(
                        "INSERT INTO jobs (lane, kind, status, options, input_source, recording_path, "
                        "vehicle_path, sweep_id, output_dir, result, artefacts, created_at, finished_at) "
                        "VALUES (:lane, 'identify', :status, '{\"points\": 20}', 'sweep', 'r.h5', 'v.toml', "
                        "1, 'out', :result, '{}', :t, :f)"
                    ),
                    {"lane": lane, "status": status, "result": result, "t": times[0], "f": finished},
                )
            c.execute(  # a scheduled test done: it refers to its sweep and its job
                sa.text(
                    "INSERT INTO schedules (bench, lane, vehicle_file, sweep_settings, job_options, "
                    "status, sweep_id, job_id, created_at) "
                    "VALUES ('b', 'north', 'v.toml', '{}', '{}', 'done', 1, 1, :t)"
                ),
                {"t": times[0]},
            )
        assert database.upgrade_schema() == ("0002", head_revision())
        with database.engine.connect() as c:
            jobs = c.execute(sa.text("SELECT id, lane, status, result FROM jobs ORDER BY id")).all()
            links = c.execute(sa.text("SELECT lane, job_id FROM result_chain ORDER BY id")).all()
            sweep = c.execute(sa.text("SELECT lane, settings FROM sweeps")).one()
            schedule = c.execute(sa.text("SELECT sweep_id, job_id, status FROM schedules")).one()
        assert tuple(schedule) == (1, 1, "done")
        assert [(j.id, j.lane, j.status) for j in jobs] == [
            (1, "north", "succeeded"),
            (2, "south", "succeeded"),
            (3, "north", "succeeded"),
            (4, "north", "failed"),
        ]
        assert "61.5" in str(jobs[0].result) and jobs[3].result is None
        assert sweep.lane == "north" and "AB-12" in str(sweep.settings)
        assert [(link.lane, link.job_id) for link in links] == [("north", 3), ("north", 1), ("south", 2)]
        report = verify_chain(database)
        assert (report.problem, report.results, report.lanes) == (None, 3, 2)
    finally:
        database.dispose()


def test_links_of_the_first_format_keep_verifying_and_the_chain_goes_on_in_the_second(
    database_url: str, tmp_path: Path
) -> None:
    """0005 -> 0006 (a chain that covers what a result means): the links there are keep format 1 and are
    numbered in their lane's order; the lane's next result is linked in format 2 after them, and an old
    result altered is still named by its format 1 hash."""
    database = Database(database_url)
    finished = datetime(2026, 11, 2, 9, 30, tzinfo=UTC)
    try:
        upgrade(database.engine, to="0002")
        with database.engine.begin() as c:
            for lane, gap in (("north", "1e-05"), ("south", "2e-05"), ("north", "3e-05")):
                c.execute(
                    sa.text(
                        "INSERT INTO jobs (lane, kind, status, options, input_source, recording_path, "
                        "vehicle_path, output_dir, result, artefacts, created_at, finished_at) VALUES "
                        "(:lane, 'identify', 'succeeded', '{}', 'upload', 'r.csv', 'v.toml', 'out', :result, "
                        "'{}', :t, :t)"
                    ),
                    {"lane": lane, "result": f'{{"gap_m": {gap}}}', "t": finished},
                )
        upgrade(database.engine, to="0005")  # 0003 chained them, in format 1
        with database.engine.connect() as c:
            before = c.execute(sa.text("SELECT id, hash FROM result_chain ORDER BY id")).all()
        assert database.upgrade_schema() == ("0005", head_revision())
        with database.engine.connect() as c:
            links = c.execute(
                sa.text("SELECT id, lane, hash, link_version, sequence FROM result_chain ORDER BY id")
            )
            old = links.all()
        assert [(link.id, link.hash) for link in old] == [tuple(link) for link in before]  # untouched
        assert [(link.lane, link.link_version, link.sequence) for link in old] == [
            ("north", 1, 1),
            ("north", 1, 2),
            ("south", 1, 1),
        ]
        assert verify_chain(database).problem is None

        store = JobStore(database, lane="north")
        job = store.create(
            "identify", {}, lambda _i: JobFiles(tmp_path / "r.csv", tmp_path / "v.toml", tmp_path)
        )
        assert store.mark_running(job.id) and store.succeed(job.id, {"gap_m": 4e-5}, {}, None)
        with database.engine.connect() as c:
            new = c.execute(
                sa.text("SELECT previous_hash, link_version, sequence FROM result_chain WHERE job_id = :id"),
                {"id": job.id},
            ).one()
        assert tuple(new) == (old[1].hash, 2, 3)
        report = verify_chain(database)
        assert (report.problem, report.results, report.lanes) == (None, 4, 2)

        with database.engine.begin() as c:
            c.execute(sa.text("UPDATE jobs SET result = '{\"gap_m\": 9e-05}' WHERE id = 3"))
        assert verify_chain(database).problem == (
            f"lane 'north': job 3's stored result was altered (it no longer matches its hash, chain link "
            f"{old[1].id})"
        )
    finally:
        database.dispose()
