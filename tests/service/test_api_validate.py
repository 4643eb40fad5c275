"""Validation jobs through the API on the real server: multipart submit at /validations (the recording and
the identified model's JSON), checked at submit, the result of `shockbench validate --json`."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from live_server import LiveServer, wait_for_status

from daq.formats.recording_csv import write_recording_csv
from estimator.identify import identify
from estimator.sweep import SweepSettings
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from simulators.vehicle_sim import SimulationSettings, default_axle, default_quarter_car, simulate

OPERATOR = "operator-key-0123456789"
VIEWER = "viewer-key-0123456789"


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Recording A (seed 1, 10 s) identified into model.json; recording B of the same car (seed 2, 12 s);
    an axle recording to refuse."""
    folder = tmp_path_factory.mktemp("validate-files")
    car = default_quarter_car()
    a = simulate(car, SimulationSettings(sweep=SweepSettings(duration_s=10.0), seed=1)).recording
    b = simulate(car, SimulationSettings(sweep=SweepSettings(duration_s=12.0), seed=2)).recording
    write_recording_csv(folder / "b.csv", b)
    (folder / "model.json").write_text(json.dumps(identify(a, car.known).to_json()))
    axle = simulate(default_axle(), SimulationSettings(sweep=SweepSettings(duration_s=4.0), seed=3)).recording
    write_recording_csv(folder / "axle.csv", axle)
    return folder


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    keys = KeyRing({OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER})
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("validate"), keys=keys)
    with LiveServer(create_app(settings)) as s:
        yield s


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client(OPERATOR) as c:
        yield c


def submit(client: httpx.Client, recording: Path, model: bytes, **form: str) -> httpx.Response:
    with recording.open("rb") as handle:
        return client.post(
            "/api/v1/validations",
            files={"recording": (recording.name, handle), "model": ("model.json", model)},
            data=form,
        )


def test_a_validation_job_gives_the_gap_on_another_recording(client: httpx.Client, files: Path) -> None:
    response = submit(client, files / "b.csv", (files / "model.json").read_bytes())
    assert response.status_code == 201, response.text
    job = response.json()
    assert job["kind"] == "validate" and response.headers["location"] == f"/api/v1/jobs/{job['id']}"
    done = wait_for_status(client, job["links"]["self"], "succeeded", "failed", "cancelled", timeout_s=600)
    assert done["status"] == "succeeded", done["error"]
    result = done["result"]
    assert set(result) == {"gap_m", "response_rms_m", "gap_ratio", "gap_diverged", "effects"}
    assert result["effects"] == []
    assert result["gap_ratio"] == pytest.approx(result["gap_m"] / result["response_rms_m"])
    assert result["gap_ratio"] < 0.05 and result["gap_diverged"] is False  # the same car: 0.015 by the CLI


def test_a_validation_that_cannot_run_is_refused_at_submit(client: httpx.Client, files: Path) -> None:
    model_bytes = (files / "model.json").read_bytes()
    model = json.loads(model_bytes)
    response = submit(client, files / "axle.csv", json.dumps(model).encode())
    assert response.status_code == 422 and response.json()["error"]["field"] == "model", response.text
    assert "quarter car" in response.json()["error"]["message"]
    del model["masses_kg"]
    response = submit(client, files / "b.csv", json.dumps(model).encode())
    assert response.status_code == 422 and response.json()["error"]["field"] == "model", response.text
    assert "missing key 'masses_kg'" in response.json()["error"]["message"]
    response = submit(client, files / "b.csv", b"{not json")
    assert response.status_code == 422 and "not JSON" in response.json()["error"]["message"]
    response = submit(client, files / "b.csv", (files / "model.json").read_bytes(), tyre="maxwell")
    assert response.status_code == 422 and response.json()["error"]["field"] == "tyre", response.text
    headers = {"Authorization": f"Bearer {VIEWER}"}
    upload = {"recording": ("b.csv", (files / "b.csv").read_bytes()), "model": ("m.json", model_bytes)}
    with httpx.Client(base_url=client.base_url, headers=headers) as viewer:
        assert viewer.post("/api/v1/validations", files=upload).status_code == 403
