"""Identification jobs through the API on the real server: submit -> queued -> running -> result and
plots; cancelling queued and running jobs; progress as Server-Sent Events."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from live_server import (
    LiveServer,
    SimulatedInputs,
    wait_for_status,
    wait_until,
)

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app

OPERATOR = "operator-key-0123456789"
AUTH = {"Authorization": f"Bearer {OPERATOR}"}
LONG_DE = {"solver": "de", "generations": "200000", "output_error": "false"}
"""A DE job that runs for minutes: something to cancel or kill."""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    keys = KeyRing({OPERATOR: Role.OPERATOR})
    with LiveServer(create_app(ServiceSettings(data_dir=tmp_path_factory.mktemp("jobs"), keys=keys))) as s:
        yield s


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, headers=AUTH, timeout=30) as c:
        yield c


def submit(client: httpx.Client, inputs: SimulatedInputs, **options: str) -> httpx.Response:
    files = {
        "recording": ("recording.csv", inputs.recording.read_bytes(), "text/csv"),
        "vehicle": ("vehicle.toml", inputs.vehicle.read_bytes(), "application/toml"),
    }
    return client.post("/api/v1/jobs", files=files, data=options)


def wait_for(client: httpx.Client, job_id: int, *statuses: str, timeout_s: float = 120) -> dict[str, Any]:
    return wait_for_status(client, f"/api/v1/jobs/{job_id}", *statuses, timeout_s=timeout_s)


def wait_running_de(client: httpx.Client, job_id: int) -> dict[str, Any]:
    """Until the job's DE reports generations (the worker is inside the estimator)."""

    def generating() -> dict[str, Any] | None:
        job = client.get(f"/api/v1/jobs/{job_id}").json()
        assert job["status"] in ("queued", "running"), job
        return job if (job["progress"] or {}).get("generation") else None

    return wait_until(generating, 120, f"job {job_id} running DE")


def test_identify_job_goes_from_submit_to_result_and_plots(
    client: httpx.Client, inputs: SimulatedInputs
) -> None:
    response = submit(client, inputs, points="12")
    assert response.status_code == 201, response.text
    job = response.json()
    assert response.headers["location"] == f"/api/v1/jobs/{job['id']}" == job["links"]["self"]
    assert job["status"] in ("queued", "running") and job["result"] is None
    assert job["options"]["points"] == 12 and job["options"]["solver"] == "exact"

    done = wait_for(client, job["id"], "succeeded", "failed")
    assert done["status"] == "succeeded", done["error"]
    result = done["result"]
    assert [c["corner"] for c in result["curves"]] == ["single"]
    assert len(result["curves"][0]["force_N"]) == 12
    assert set(result["curves"][0]["tanh"]) == {"c_s", "kappa", "mu", "beta"}
    assert abs(result["masses_kg"]["sprung"] / 375.0 - 1) < 0.03
    assert set(result["inspection"]) >= {"eusama_percent", "phase_shift_min_deg", "damping_ratio"}
    assert result["gap_m"] is not None and result["gap_m"] > 0
    assert done["progress"]["stage"] == "done" and done["started_at"] <= done["finished_at"]

    png = client.get(done["links"]["plot_png"])
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    assert png.content.startswith(b"\x89PNG\r\n\x1a\n")
    svg = client.get(done["links"]["plot_svg"])
    assert svg.status_code == 200 and svg.headers["content-type"].startswith("image/svg+xml")
    assert b"<svg" in svg.content

    listed = client.get("/api/v1/jobs", params={"status": "succeeded"}).json()
    assert job["id"] in [j["id"] for j in listed["jobs"]]
    assert all(j["result"] is None for j in listed["jobs"])  # the list is light; GET a job for its result


def test_cancel_a_queued_job_then_the_running_one(client: httpx.Client, inputs: SimulatedInputs) -> None:
    restarts = client.get("/api/v1/status").json()["worker"]["restarts"]
    running = submit(client, inputs, **LONG_DE).json()
    queued = submit(client, inputs).json()
    wait_running_de(client, running["id"])

    cancelled = client.post(f"/api/v1/jobs/{queued['id']}/cancel")
    assert cancelled.status_code == 200
    assert cancelled.json()["status"] == "cancelled"

    asked = client.post(f"/api/v1/jobs/{running['id']}/cancel")
    assert asked.status_code == 202 and asked.json()["status"] == "running"
    stopped = wait_for(client, running["id"], "cancelled", "failed", "succeeded", timeout_s=30)
    assert stopped["status"] == "cancelled"
    assert stopped["progress"]["generation"] < 200000
    # the DE stopped through its cancel Event: the worker was not killed
    assert client.get("/api/v1/status").json()["worker"]["restarts"] == restarts

    again = client.post(f"/api/v1/jobs/{running['id']}/cancel")
    assert again.status_code == 409 and again.json()["error"]["code"] == "conflict"
    no_plot = client.get(f"/api/v1/jobs/{running['id']}/plot.png")
    assert no_plot.status_code == 409
    assert wait_for(client, queued["id"], "cancelled")["started_at"] is None


def test_unknown_job_is_a_typed_404(client: httpx.Client) -> None:
    for path in ("/api/v1/jobs/987654", "/api/v1/jobs/987654/events", "/api/v1/jobs/987654/plot.svg"):
        response = client.get(path)
        assert response.status_code == 404
        assert response.json() == {"error": {"code": "not_found", "message": "no job 987654"}}


def read_events(response: httpx.Response) -> Iterator[tuple[str, dict[str, Any]]]:
    event, data = None, []
    for line in response.iter_lines():
        if line.startswith("event: "):
            event = line.removeprefix("event: ")
        elif line.startswith("data: "):
            data.append(line.removeprefix("data: "))
        elif not line and event is not None:
            yield event, json.loads("".join(data))
            event, data = None, []


def test_progress_arrives_as_server_sent_events_then_the_result(
    client: httpx.Client, server: LiveServer, inputs: SimulatedInputs
) -> None:
    blocker = submit(client, inputs, **LONG_DE).json()
    job = submit(client, inputs, solver="de", generations="400", output_error="false").json()
    wait_running_de(client, blocker["id"])  # so that `job` waits in the queue while we subscribe
    events: list[tuple[str, dict[str, Any]]] = []
    with (
        httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as stream_client,
        stream_client.stream("GET", f"/api/v1/jobs/{job['id']}/events") as response,
    ):
        assert response.headers["content-type"].startswith("text/event-stream")
        stream = read_events(response)
        events.append(next(stream))
        assert events[0][0] == "state" and events[0][1]["status"] == "queued"
        assert client.post(f"/api/v1/jobs/{blocker['id']}/cancel").status_code == 202
        events.extend(stream)
    names = [name for name, _ in events]
    assert names[-1] == "succeeded" and names.count("succeeded") == 1
    assert "running" in [data.get("status") for name, data in events if name == "state"]
    reports = [data for name, data in events if name == "progress"]
    assert all(p["job_id"] == job["id"] for p in reports)
    progress = [p for p in reports if p["stage"] == "differential evolution" and p["generation"]]
    assert progress, names
    assert all(p["generations"] == 400 and p["best_objective"] > 0 for p in progress)
    assert progress[-1]["generation"] == 400 and progress[-1]["eta_s"] == pytest.approx(0, abs=1e-9)
    assert [p["generation"] for p in progress] == sorted(p["generation"] for p in progress)
    assert reports[-1]["stage"] == "done" and reports[-1]["generation"] == 400
    final = events[-1][1]
    assert final["result"]["solver"] == "de" and final["result"]["curves"]
    # polling gives the same outcome
    assert client.get(f"/api/v1/jobs/{job['id']}").json()["result"] == final["result"]


def test_events_of_a_finished_job_are_its_state_and_outcome(
    client: httpx.Client, inputs: SimulatedInputs
) -> None:
    job = submit(client, inputs, output_error="false").json()
    wait_for(client, job["id"], "succeeded")
    with client.stream("GET", f"/api/v1/jobs/{job['id']}/events") as response:
        assert [name for name, _ in read_events(response)] == ["state", "succeeded"]


def test_jobs_live_in_the_data_directory_by_id(server: LiveServer, tmp_path: Path) -> None:
    settings = server.app.state.services.settings
    folders = sorted(p.name for p in settings.jobs_dir.iterdir())
    assert folders and all((settings.jobs_dir / f / "recording.csv").is_file() for f in folders)
    assert not any(settings.uploads_dir.iterdir())  # no upload left behind, accepted or refused
