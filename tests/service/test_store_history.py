"""A vehicle's history from the store, on SQLite and PostgreSQL: every test of the vehicle across lanes,
newest first, each with its newest *succeeded* identification (not a newer failed one, not a diagnosis),
and the trend of its damping since the first test; `shockbench history` prints the same."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa

from service.api.history import vehicle_history
from service.store.database import Database
from service.store.history import vehicle_tests
from service.store.jobs import JobFiles, JobStore
from service.store.models import JobKind, SweepRow, SweepStatus
from service.store.schema import BASELINE, upgrade
from service.store.sweeps import SweepStore


def linear_result(c_Ns_per_m: float, eusama: float = 55.0) -> dict[str, Any]:
    """An identification's result (the keys the history reads) with a linear damper F = c·v."""
    velocity = [-0.6, -0.2, 0.0, 0.2, 0.6]
    return {
        "curves": [
            {"corner": "single", "velocity_m_s": velocity, "force_N": [c_Ns_per_m * v for v in velocity]}
        ],
        "inspection": {
            "eusama_percent": eusama,
            "phase_shift_min_deg": 42.0,
            "damping_ratio": 0.3,
            "equivalent_damping_Ns_per_m": c_Ns_per_m,
        },
        "verdict": {"outcome": "pass", "thresholds_version": "t1", "reasons": [], "thresholds": {"x": 1.0}},
    }


def run_job(store: JobStore, sweep_id: int, kind: JobKind, result: dict[str, Any] | None, tmp: Path) -> int:
    """A job on the sweep that ran and succeeded with `result`, or failed (result None)."""
    files = JobFiles(tmp / "r.csv", tmp / "v.toml", tmp)
    job = store.create(kind.value, {}, lambda _i: files, input_source="sweep", sweep_id=sweep_id)
    assert store.mark_running(job.id)
    if result is None:
        assert store.fail(job.id, "did not converge")
    else:
        assert store.succeed(job.id, result, {}, None)
    return job.id


def fill(database: Database, tmp: Path) -> dict[str, int]:
    """Three tests of AB-123 on two lanes (the middle one never identified), one of another vehicle."""
    place = lambda i: (tmp / f"{i}.h5", tmp / f"{i}.toml")  # noqa: E731
    ids: dict[str, int] = {}
    for name, lane, vehicle, c in (
        ("first", "north", "AB-123", 2000.0),
        ("failed", "south", "ab-123", None),
        ("other", "south", "XY-9", 900.0),
        ("last", "south", "AB-123", 1500.0),
    ):
        sweeps, jobs = SweepStore(database, lane=lane), JobStore(database, lane=lane)
        settings = {"vehicle_id": vehicle, "tyre_pressure_bar": 2.2, "operator_name": f"op {name}"}
        sweep = sweeps.create("bench", settings, place)
        ids[name] = sweep.id
        if c is None:
            sweeps.finish(sweep.id, SweepStatus.FAILED, complete=False, reason="emergency stop")
            continue
        sweeps.finish(sweep.id, SweepStatus.COMPLETE, complete=True, reason=None)
        ids[f"{name} job"] = run_job(jobs, sweep.id, JobKind.IDENTIFY, linear_result(c), tmp)
        if name == "last":  # a newer identification that failed, and a diagnosis: neither is shown
            run_job(jobs, sweep.id, JobKind.IDENTIFY, None, tmp)
            run_job(jobs, sweep.id, JobKind.DIAGNOSE, {"conclusion": "fine"}, tmp)
    return ids


def test_every_test_of_the_vehicle_newest_first_with_its_newest_succeeded_identification(
    database: Database, tmp_path: Path
) -> None:
    ids = fill(database, tmp_path)
    tests = vehicle_tests(database, "Ab-123")
    assert [t.sweep.id for t in tests] == [ids["last"], ids["failed"], ids["first"]]
    assert [t.sweep.lane for t in tests] == ["south", "south", "north"]
    assert [t.identification.id if t.identification else None for t in tests] == [
        ids["last job"],
        None,
        ids["first job"],
    ]
    assert vehicle_tests(database, "nobody") == []
    with database.engine.connect() as c:
        chained = dict(c.execute(sa.text("SELECT job_id, hash FROM result_chain")).all())
    assert [t.result_hash for t in tests] == [chained[ids["last job"]], None, chained[ids["first job"]]]


def test_the_history_carries_curves_figures_verdict_and_the_trend(database: Database, tmp_path: Path) -> None:
    ids = fill(database, tmp_path)
    history = vehicle_history(database, "AB-123")
    last, failed, first = history.tests
    assert (last.lane, last.operator_name, last.tyre_pressure_bar) == ("south", "op last", 2.2)
    assert last.curves[0].force_N == pytest.approx([-900.0, -300.0, 0.0, 300.0, 900.0])
    assert last.inspection is not None and last.inspection.equivalent_damping_Ns_per_m == 1500.0
    assert last.verdict is not None and last.verdict.outcome == "pass"
    assert (failed.status, failed.curves, failed.inspection, failed.verdict) == ("failed", [], None, None)
    assert first.identification_job_id == ids["first job"]

    (corner,) = history.trend.corners
    assert corner.corner == "single" and [t.sweep_id for t in corner.tests] == [ids["first"], ids["last"]]
    velocities = history.trend.reference_velocities_m_s
    assert corner.tests[0].force_N == pytest.approx([2000.0 * v for v in velocities])
    assert corner.tests[1].force_N == pytest.approx([1500.0 * v for v in velocities])
    assert corner.tests[1].change_percent == pytest.approx([-25.0] * len(velocities))  # 1500 vs 2000 N·s/m


def shockbench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "service.cli.main", *args], capture_output=True, text=True, timeout=120
    )


def test_the_history_command_prints_the_same(database: Database, database_url: str, tmp_path: Path) -> None:
    ids = fill(database, tmp_path)
    as_json = shockbench("history", "ab-123", "--database", database_url, "--json")
    assert as_json.returncode == 0, as_json.stderr
    assert json.loads(as_json.stdout) == vehicle_history(database, "ab-123").model_dump(mode="json")
    text = shockbench("history", "AB-123", "--database", database_url)
    assert text.returncode == 0, text.stderr
    assert "3 test(s)" in text.stdout and "op last" in text.stdout and "-25.0%" in text.stdout
    assert str(ids["first job"]) in text.stdout

    unknown = shockbench("history", "NOBODY", "--database", database_url)
    assert unknown.returncode == 2 and "no test of vehicle 'NOBODY'" in unknown.stderr
    assert unknown.stderr.strip().count("\n") == 0


def test_the_history_command_names_a_missing_or_old_database(tmp_path: Path) -> None:
    missing = shockbench("history", "AB-1", "--data", str(tmp_path / "nowhere"))
    assert missing.returncode == 2 and "no database in" in missing.stderr
    assert not (tmp_path / "nowhere").exists()  # reading created nothing
    url = f"sqlite:///{tmp_path / 'old.sqlite3'}"
    old = Database(url)
    upgrade(old.engine, to=BASELINE)
    old.dispose()
    refused = shockbench("history", "AB-1", "--database", url)
    assert refused.returncode == 2 and "shockbench db upgrade" in refused.stderr
    assert refused.stderr.strip().count("\n") == 0


def test_a_lane_with_a_local_store_lists_its_own_tests_and_the_other_lanes_from_the_central_database(
    database: Database, tmp_path: Path
) -> None:
    central_ids = fill(database, tmp_path)  # north's "first" is there too: synced earlier
    local = Database(f"sqlite:///{tmp_path / 'local.sqlite3'}", outbox=True)
    local.upgrade_schema()
    try:
        place = lambda i: (tmp_path / f"l{i}.h5", tmp_path / f"l{i}.toml")  # noqa: E731
        sweeps = SweepStore(local, lane="north")
        first = sweeps.create("bench", {"vehicle_id": "AB-123"}, place)  # the lane's own copy of "first"
        newest = sweeps.create("bench", {"vehicle_id": "ab-123"}, place)  # not synced yet
        for sweep in (first, newest):
            sweeps.finish(sweep.id, SweepStatus.COMPLETE, complete=True, reason=None)
        job = run_job(
            JobStore(local, lane="north"), newest.id, JobKind.IDENTIFY, linear_result(1200.0), tmp_path
        )
        with database.sessions() as session:  # the copy was tested when the central "first" was
            tested = session.scalar(sa.select(SweepRow.created_at).where(SweepRow.id == central_ids["first"]))
        with local.transaction() as session:
            session.execute(sa.update(SweepRow).where(SweepRow.id == first.id).values(created_at=tested))

        history = vehicle_history(local, "AB-123", central=database, lane="north")
        assert [(t.lane, t.sweep_id) for t in history.tests] == [
            ("north", newest.id),
            ("south", central_ids["last"]),
            ("south", central_ids["failed"]),
            ("north", first.id),
        ]
        assert history.tests[0].identification_job_id == job and not history.other_lanes_missing
        (corner,) = history.trend.corners  # the lane's copy of "first" has no identification here
        assert [t.sweep_id for t in corner.tests] == [central_ids["last"], newest.id]
        assert corner.tests[-1].change_percent == pytest.approx([-20.0] * 6)  # 1200 vs 1500 N·s/m

        away = Database("postgresql+psycopg://postgres@127.0.0.1:9/none?connect_timeout=2")
        alone = vehicle_history(local, "AB-123", central=away, lane="north")
        assert [t.sweep_id for t in alone.tests] == [newest.id, first.id] and alone.other_lanes_missing
    finally:
        local.dispose()
