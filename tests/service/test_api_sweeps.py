"""Sweeps through the API on the real server with the in-process simulated bench (serve --simulated):
bench status, the safety envelope and the vehicle file checked before anything moves, one sweep at a time,
recording download, abort, emergency stop, recovery after a restart, and sweep -> identification job ->
the simulator's true curve."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from live_server import LiveServer, wait_until
from live_server import wait_for_status as wait_for

from daq.formats import vehicle_file
from daq.formats.vehicle_file import format_vehicle
from estimator.damper import PiecewiseLinearCurve
from estimator.vehicle import VehicleParameters
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.store.database import Database
from service.store.models import SweepStatus
from service.store.sweeps import RESTART_REASON, SweepStore
from simulators.vehicle_sim import default_quarter_car, true_damper

OPERATOR = "operator-key-0123456789"
VIEWER = "viewer-key-0123456789"
AUTH = {"Authorization": f"Bearer {OPERATOR}"}
VEHICLE_TOML = format_vehicle(default_quarter_car().known)
SHORT = {"duration_s": 2, "settle_s": 0.5, "vehicle_toml": VEHICLE_TOML}
LONG = {"duration_s": 300, "settle_s": 0.5, "vehicle_toml": VEHICLE_TOML}  # the envelope's longest
"""A sweep that runs for minutes on the simulated clock: something to abort or stop."""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    keys = KeyRing({OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER})
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("sweeps"), keys=keys, simulated=True)
    with LiveServer(create_app(settings)) as s:
        yield s


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client(OPERATOR) as c:
        yield c


def start_sweeping(client: httpx.Client, body: dict[str, Any]) -> dict[str, Any]:
    """Start a sweep and wait until the plate moves (progress in phase sweeping)."""
    response = client.post("/api/v1/sweeps", json=body)
    assert response.status_code == 201, response.text
    sweep = response.json()

    def sweeping() -> dict[str, Any] | None:
        now = client.get(f"/api/v1/sweeps/{sweep['id']}").json()
        assert now["status"] in ("requested", "running"), now
        return now if (now["progress"] or {}).get("phase") == "sweeping" else None

    return wait_until(sweeping, 60, f"sweep {sweep['id']} sweeping")


def test_bench_state_devices_and_status(client: httpx.Client) -> None:
    bench = client.get("/api/v1/bench").json()
    assert bench["simulated"] is True and bench["model"] == "quarter-car"
    assert bench["busy"] is False and bench["sweep_id"] is None and bench["progress"] is None
    devices = client.get("/api/v1/bench/devices").json()["devices"]
    kinds = sorted(d["kind"] for d in devices)
    assert kinds.count("exciter") == 1 and kinds.count("laser") >= 1
    status = client.get("/api/v1/status").json()
    assert status["bench"]["name"] == bench["name"] and status["bench"]["busy"] is False


@pytest.mark.parametrize("path", ["/api/v1/sweeps", "/api/v1/emergency-stop", "/api/v1/sweeps/1/abort"])
def test_moving_the_plate_needs_an_operator(server: LiveServer, path: str) -> None:
    body = SHORT if path == "/api/v1/sweeps" else None
    anonymous = httpx.post(server.url + path, json=body)
    assert anonymous.status_code == 401 and anonymous.json()["error"]["code"] == "unauthorized"
    viewer = httpx.post(server.url + path, json=body, headers={"Authorization": f"Bearer {VIEWER}"})
    assert viewer.status_code == 403 and viewer.json()["error"]["code"] == "forbidden"
    bench = httpx.get(server.url + "/api/v1/bench", headers={"Authorization": f"Bearer {VIEWER}"})
    assert bench.status_code == 200 and bench.json()["busy"] is False


def test_envelope_and_vehicle_file_are_checked_before_anything_moves(client: httpx.Client) -> None:
    before = client.get("/api/v1/sweeps").json()["total"]
    response = client.post("/api/v1/sweeps", json={**SHORT, "amplitude_m": 0.01})
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert error["field"] == "amplitude_m" and "safety envelope" in error["message"]

    response = client.post("/api/v1/sweeps", json={**SHORT, "stop_Hz": 500})
    assert response.status_code == 422 and response.json()["error"]["field"] == "stop_Hz"

    response = client.post("/api/v1/sweeps", json={**SHORT, "vehicle_toml": "[vehicle\nmodel = 1"})
    assert response.status_code == 422, response.text
    assert response.json()["error"]["field"] == "vehicle_toml"

    response = client.post("/api/v1/sweeps", json={k: v for k, v in SHORT.items() if k != "vehicle_toml"})
    assert response.status_code == 422 and response.json()["error"]["field"] == "vehicle_toml"

    assert client.get("/api/v1/sweeps").json()["total"] == before
    assert client.get("/api/v1/bench").json()["busy"] is False


def test_short_sweep_completes_and_its_recording_downloads(
    client: httpx.Client, monkeypatch: pytest.MonkeyPatch
) -> None:
    parsed: list[str] = []  # the vehicle file is parsed once, at the edge; the plan carries it down
    real_parse = vehicle_file.parse_vehicle

    def counting_parse(text: str, source: str = "vehicle file") -> VehicleParameters:
        parsed.append(source)
        return real_parse(text, source)

    monkeypatch.setattr(vehicle_file, "parse_vehicle", counting_parse)
    response = client.post("/api/v1/sweeps", json=SHORT)
    assert response.status_code == 201, response.text
    sweep = response.json()
    assert response.headers["location"] == f"/api/v1/sweeps/{sweep['id']}" == sweep["links"]["self"]
    assert sweep["status"] in ("requested", "running", "complete")
    assert sweep["settings"]["duration_s"] == 2 and sweep["settings"]["settle_s"] == 0.5
    assert sweep["operator"] and sweep["recording_file"] == f"{sweep['id']}.h5"

    done = wait_for(client, sweep["links"]["self"], "complete", "failed", "aborted")
    assert done["status"] == "complete" and done["complete"] is True, done
    assert done["reason"] is None and done["finished_at"] is not None
    assert parsed == ["vehicle_toml"]

    csv = client.get(done["links"]["recording_csv"])
    assert csv.status_code == 200, csv.text
    assert csv.headers["content-type"].startswith("text/csv")
    lines = [line for line in csv.text.splitlines() if line and not line.startswith("#")]
    assert lines[0] == "t,x_s,x_t,x_r"
    assert len(lines) - 1 == 2501  # (2 s sweep + 0.5 s settling) at 1 kHz, both ends included
    listed = client.get("/api/v1/sweeps").json()
    assert listed["sweeps"][0]["id"] == sweep["id"] and listed["total"] >= 1


def test_one_sweep_at_a_time_then_abort(client: httpx.Client) -> None:
    sweep = start_sweeping(client, LONG)
    path = sweep["links"]["self"]
    bench = client.get("/api/v1/bench").json()
    assert bench["busy"] is True and bench["sweep_id"] == sweep["id"]
    assert 0 <= bench["progress"]["fraction"] < 1
    assert client.get("/api/v1/status").json()["bench"]["sweep_id"] == sweep["id"]

    busy = client.post("/api/v1/sweeps", json=SHORT)
    assert busy.status_code == 409 and busy.json()["error"]["code"] == "bench_busy"
    early = client.get(sweep["links"]["recording_csv"])
    assert early.status_code == 409
    assert client.post(sweep["links"]["jobs"], json={}).status_code == 409

    abort = client.post(sweep["links"]["abort"])
    assert abort.status_code == 202, abort.text
    done = wait_for(client, path, "complete", "failed", "aborted", timeout_s=60)
    assert done["status"] == "aborted" and done["reason"] == "aborted by the operator", done
    assert done["complete"] is False
    assert client.post(sweep["links"]["abort"]).status_code == 409
    wait_until(lambda: not client.get("/api/v1/bench").json()["busy"], 30, "bench idle")


def test_emergency_stop_ends_the_running_sweep(client: httpx.Client) -> None:
    sweep = start_sweeping(client, LONG)
    response = client.post("/api/v1/emergency-stop")
    assert response.status_code == 200, response.text
    assert response.json()["sweep_id"] == sweep["id"]
    done = wait_for(client, sweep["links"]["self"], "complete", "failed", "aborted", timeout_s=60)
    assert done["status"] == "failed" and done["reason"] == "emergency stop by the operator", done
    wait_until(lambda: not client.get("/api/v1/bench").json()["busy"], 30, "bench idle")

    idle = client.post("/api/v1/emergency-stop")  # nothing running: straight to the drive
    assert idle.status_code == 200 and idle.json()["sweep_id"] is None
    assert idle.json()["done"] == "emergency stop sent to the drive", idle.text


def test_sweep_then_identification_job_finds_the_true_curve(server: LiveServer, client: httpx.Client) -> None:
    body = {"start_Hz": 0, "stop_Hz": 20, "amplitude_m": 0.004, "duration_s": 12, "settle_s": 1}
    response = client.post("/api/v1/sweeps", json={**body, "vehicle_toml": VEHICLE_TOML})
    assert response.status_code == 201, response.text
    sweep = wait_for(client, response.headers["location"], "complete", "failed", "aborted")
    assert sweep["status"] == "complete", sweep

    response = client.post(sweep["links"]["jobs"], json={})
    assert response.status_code == 201, response.text
    job = response.json()
    assert response.headers["location"] == f"/api/v1/jobs/{job['id']}"
    assert job["input_source"] == "sweep" and job["sweep_id"] == sweep["id"]
    done = wait_for(client, response.headers["location"], "succeeded", "failed", "cancelled", timeout_s=300)
    assert done["status"] == "succeeded", done["error"]
    # the job read the recording where acquisition wrote it: the sweep's HDF5 file, no CSV copy beside it
    record = server.app.state.services.jobs.get(job["id"])
    assert record is not None and record.recording_path.endswith(f"{sweep['id']}.h5")
    assert list(Path(record.recording_path).parent.glob("*.csv")) == []

    curve = done["result"]["curves"][0]
    identified = PiecewiseLinearCurve(np.array(curve["velocity_m_s"]), np.array(curve["force_N"]))
    truth = true_damper(default_quarter_car().dampers[0])
    grid = np.linspace(-0.3, 0.3, 200)
    error = np.sqrt(np.mean((identified.force(grid) - truth.force(grid)) ** 2)) / np.max(
        np.abs(truth.force(grid))
    )
    assert error < 0.03, f"RMS curve error {error:.2%}"


def test_without_a_bench_sweeps_answer_503_and_restart_fails_running_sweeps(tmp_path: Path) -> None:
    settings = ServiceSettings(data_dir=tmp_path, keys=KeyRing({OPERATOR: Role.OPERATOR}))
    database = Database(settings.resolved_database_url)
    database.upgrade_schema()
    store = SweepStore(database)
    cut_off = store.create("bench", {}, lambda i: (tmp_path / f"{i}.h5", tmp_path / f"{i}.toml"))
    store.mark_running(cut_off.id)
    database.dispose()

    with LiveServer(create_app(settings)) as server, httpx.Client(base_url=server.url, headers=AUTH) as c:
        for method, path, body in (
            ("GET", "/api/v1/bench", None),
            ("POST", "/api/v1/sweeps", SHORT),
            ("POST", "/api/v1/emergency-stop", None),
        ):
            response = c.request(method, path, json=body)
            assert response.status_code == 503, response.text
            error = response.json()["error"]
            assert error["code"] == "no_bench"
            assert error["message"] == "no bench: start serve with --simulated or --config"
        assert c.get("/api/v1/status").json()["bench"] is None
        sweep = c.get(f"/api/v1/sweeps/{cut_off.id}").json()
        assert sweep["status"] == SweepStatus.FAILED.value and sweep["reason"] == RESTART_REASON
