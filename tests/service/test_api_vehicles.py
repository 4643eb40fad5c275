"""A vehicle's history through the API, on the real server with the simulated bench: two tests of one
vehicle (its id written differently), each identified by the worker, read back newest first with what the
operator recorded, the curves, lane figures and verdict, and the trend since the first test; the results
the worker stored are chained (`verify` holds)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from live_server import LiveServer
from live_server import wait_for_status as wait_for
from sqlalchemy import select

from daq.formats.vehicle_file import format_vehicle
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.store.chain_anchor import HeadLog
from service.store.database import Database
from service.store.models import JobRow, SweepRow
from service.store.result_chain import verify_chain
from simulators.vehicle_sim import default_quarter_car

OPERATOR = "operator-key-for-vehicles-1"
VIEWER = "viewer-key-for-vehicles-001"
SHORT = {"duration_s": 3, "settle_s": 0.5, "vehicle_toml": format_vehicle(default_quarter_car().known)}
TESTS = [
    {"vehicle_id": "WVW-ZZZ 1K", "tyre_pressure_bar": 2.3, "operator_name": "A. Mechanic"},
    {"vehicle_id": "wvw-zzz 1k", "tyre_pressure_bar": 2.1, "operator_name": "B. Mechanic"},
]


@pytest.fixture(scope="module")
def settings(tmp_path_factory: pytest.TempPathFactory) -> ServiceSettings:
    keys = KeyRing({OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER})
    data_dir = tmp_path_factory.mktemp("vehicles")
    return ServiceSettings(data_dir=data_dir, keys=keys, simulated=True, lane="lane-1")


@pytest.fixture(scope="module")
def server(settings: ServiceSettings) -> Iterator[LiveServer]:
    with LiveServer(create_app(settings)) as s:
        yield s


def run_test(operator: httpx.Client, test: dict[str, Any]) -> tuple[int, int]:
    """A sweep of the vehicle and its identification; (sweep id, job id)."""
    started = operator.post("/api/v1/sweeps", json={**SHORT, **test})
    assert started.status_code == 201, started.text
    sweep_id = started.json()["id"]
    done = wait_for(operator, f"/api/v1/sweeps/{sweep_id}", "complete", "failed", "aborted")
    assert done["status"] == "complete", done["reason"]
    job = operator.post(f"/api/v1/sweeps/{sweep_id}/jobs", json={})
    assert job.status_code == 201, job.text
    result = wait_for(operator, f"/api/v1/jobs/{job.json()['id']}", "succeeded", "failed", timeout_s=300)
    assert result["status"] == "succeeded", result["error"]
    return sweep_id, job.json()["id"]


def test_a_vehicles_tests_newest_first_with_curves_figures_verdict_and_trend(
    server: LiveServer, settings: ServiceSettings
) -> None:
    with server.client(OPERATOR) as operator:
        first, second = (run_test(operator, test) for test in TESTS)
    with server.client(VIEWER) as viewer:
        answer = viewer.get("/api/v1/vehicles/Wvw-Zzz 1k/results")
        assert answer.status_code == 200, answer.text
        history = answer.json()
        assert viewer.get("/api/v1/vehicles/NOBODY-1/results").status_code == 404
        bad = viewer.get("/api/v1/vehicles/<script>/results")
        assert bad.status_code == 422 and bad.json()["error"]["field"] == "vehicle_id"

    newest, oldest = history["tests"]
    assert [newest["sweep_id"], oldest["sweep_id"]] == [second[0], first[0]]
    assert [newest["identification_job_id"], oldest["identification_job_id"]] == [second[1], first[1]]
    for shown, recorded in ((newest, TESTS[1]), (oldest, TESTS[0])):
        assert {key: shown[key] for key in recorded} == recorded
        assert shown["lane"] == "lane-1" and shown["status"] == "complete"
        (curve,) = shown["curves"]
        assert curve["corner"] == "single" and len(curve["velocity_m_s"]) == len(curve["force_N"]) >= 10
        assert shown["inspection"]["eusama_percent"] is not None
        assert shown["verdict"]["outcome"] in ("pass", "check", "fail")
        assert len(shown["result_hash"]) == 64 and int(shown["result_hash"], 16) >= 0

    trend = history["trend"]
    velocities = trend["reference_velocities_m_s"]
    (corner,) = trend["corners"]
    assert [t["sweep_id"] for t in corner["tests"]] == [first[0], second[0]]  # oldest first
    baseline, later = corner["tests"]
    inside = [i for i, f in enumerate(baseline["force_N"]) if f is not None]
    assert inside and all(baseline["change_percent"][i] == 0.0 for i in inside)
    for i in inside:  # the same vehicle and damper: the damping is within a few % of the first test
        if later["force_N"][i] is not None:
            assert abs(later["change_percent"][i]) < 10.0  # measured: 0.2-2.1%
            assert (later["force_N"][i] > 0) == (velocities[i] > 0)

    database = Database(settings.resolved_database_url)
    heads, _ = HeadLog.in_data_dir(settings.data_dir).checkpoints()  # the service logged each new head
    try:
        report = verify_chain(database, checkpoints=heads)
        with database.sessions() as session:  # each link covers its sweep's recording, as hashed at its end
            recordings = session.scalars(select(SweepRow.recording_sha256).order_by(SweepRow.id)).all()
            jobs = session.scalars(select(JobRow.recording_sha256).order_by(JobRow.id)).all()
    finally:
        database.dispose()
    assert (report.problem, report.results, report.lanes, report.checkpoints) == (None, 2, 1, 2)
    assert [h.head.sequence for h in heads] == [1, 2] and all(recordings) and jobs == recordings
