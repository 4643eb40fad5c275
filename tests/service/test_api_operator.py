"""What the operator page needs from the API, on the real server with the simulated bench: the key's role,
the test's record (vehicle id, tyre pressure, operator) stored with the sweep and searchable, the live
stream of the bench (state and decimated channels), the HDF5 download, the newest job of a sweep and the
verdict stored with an identification."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest
from live_server import LiveServer, wait_until
from live_server import wait_for_status as wait_for

from daq.formats.vehicle_file import format_vehicle
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from simulators.vehicle_sim import default_quarter_car

OPERATOR = "operator-key-for-the-page-01"
VIEWER = "viewer-key-for-the-page-0001"
VEHICLE_TOML = format_vehicle(default_quarter_car().known)
TEST = {"vehicle_id": "WVW-ZZZ 1K", "tyre_pressure_bar": 2.3, "operator_name": "A. Mechanic"}
SHORT = {"duration_s": 3, "settle_s": 0.5, "vehicle_toml": VEHICLE_TOML}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    keys = KeyRing({OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER})
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("page"), keys=keys, simulated=True)
    with LiveServer(create_app(settings)) as s:
        yield s


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client(OPERATOR) as c:
        yield c


def events(lines: Iterator[str]) -> Iterator[tuple[str, dict[str, Any]]]:
    """(name, data) of each Server-Sent Event on the stream's lines; comments skipped."""
    name, data = "", ""
    for line in lines:
        if line.startswith("event: "):
            name = line[7:]
        elif line.startswith("data: "):
            data = line[6:]
        elif line == "" and name:
            yield name, json.loads(data)
            name, data = "", ""


def test_whoami_names_the_role(server: LiveServer) -> None:
    for key, role in ((VIEWER, "viewer"), (OPERATOR, "operator")):
        answer = httpx.get(f"{server.url}/api/v1/whoami", headers={"Authorization": f"Bearer {key}"})
        assert answer.status_code == 200 and answer.json()["role"] == role
    stranger = httpx.get(f"{server.url}/api/v1/whoami", headers={"Authorization": "Bearer nope"})
    assert stranger.status_code == 401


def test_a_bad_test_field_is_named(client: httpx.Client) -> None:
    for field, value in (("tyre_pressure_bar", 25.0), ("vehicle_id", "<script>"), ("operator_name", "")):
        answer = client.post("/api/v1/sweeps", json={**SHORT, field: value})
        assert answer.status_code == 422, answer.text
        assert answer.json()["error"]["field"] == field


def test_live_stream_then_record_search_download_job_and_verdict(
    server: LiveServer, client: httpx.Client
) -> None:
    headers = {"Authorization": f"Bearer {VIEWER}"}
    seen: dict[str, Any] = {"states": [], "t_s": [], "x_t": [], "sweep_ids": set()}
    with httpx.stream("GET", f"{server.url}/api/v1/bench/live", headers=headers, timeout=60) as stream:
        assert stream.headers["content-type"].startswith("text/event-stream")
        lines = stream.iter_lines()
        name, first = next(events(lines))
        assert name == "state" and (first["busy"], first["sweep_id"], first["progress"]) == (
            False,
            None,
            None,
        )
        assert {d["kind"] for d in first["devices"]} == {"exciter", "laser"}
        assert all(d["state"] for d in first["devices"])
        started = client.post("/api/v1/sweeps", json={**SHORT, **TEST})
        assert started.status_code == 201, started.text
        sweep = started.json()
        for name, data in events(lines):
            if name == "state":
                seen["states"].append(data)
                if not data["busy"] and len(seen["states"]) > 1 and seen["t_s"]:
                    break
            elif name == "samples":
                assert set(data["channels"]) == {"x_s", "x_t", "x_r"}
                seen["t_s"] += data["t_s"]
                seen["x_t"] += data["channels"]["x_t"]
                seen["sweep_ids"].add(data["sweep_id"])
    assert seen["sweep_ids"] == {sweep["id"]}
    sweeping = [
        s for s in seen["states"] if s["busy"] and s["progress"] and s["progress"]["phase"] == "sweeping"
    ]
    assert sweeping
    during = {d["kind"]: d["state"] for d in sweeping[-1]["devices"]}
    assert during["exciter"].startswith("sweeping at ") and during["laser"].startswith("reading: ")
    after = client.get("/api/v1/bench/devices").json()["devices"]
    lasers = [d["state"] for d in after if d["kind"] == "laser"]
    assert lasers and all(state.startswith("idle; last sweep: ") for state in lasers)
    t_s = np.array(seen["t_s"])
    assert np.allclose(np.diff(t_s), 0.01)  # every 10th row of 1 kHz: each once, in order, none lost
    assert t_s[-1] > SHORT["duration_s"]
    wheel = np.array([np.nan if v is None else v for v in seen["x_t"]])
    assert np.nanmax(np.abs(wheel)) > 1e-4  # the wheel moved on the chart

    done = wait_for(client, f"/api/v1/sweeps/{sweep['id']}", "complete", "failed", "aborted")
    assert done["status"] == "complete" and done["test"] == TEST and done["latest_job_id"] is None
    other = client.post("/api/v1/sweeps", json={**SHORT, "vehicle_id": "OTHER-1"})
    wait_for(client, f"/api/v1/sweeps/{other.json()['id']}", "complete", "failed", "aborted")
    found = client.get("/api/v1/sweeps", params={"vehicle_id": "wvw-zzz 1k"}).json()
    assert [s["id"] for s in found["sweeps"]] == [sweep["id"]] and found["total"] == 1

    h5 = client.get(done["links"]["recording_h5"])
    assert h5.status_code == 200 and h5.content[:8] == b"\x89HDF\r\n\x1a\n"

    job = client.post(f"/api/v1/sweeps/{sweep['id']}/jobs", json={})
    assert job.status_code == 201, job.text
    assert client.get(f"/api/v1/sweeps/{sweep['id']}").json()["latest_job_id"] == job.json()["id"]
    result = wait_for(client, f"/api/v1/jobs/{job.json()['id']}", "succeeded", "failed", timeout_s=300)
    assert result["status"] == "succeeded", result["error"]
    verdict = result["result"]["verdict"]
    assert verdict["outcome"] in ("pass", "check", "fail")
    assert verdict["thresholds_version"] and verdict["thresholds"]["phase_fail_below_deg"] == 35.0
    assert (verdict["outcome"] == "pass") == (not verdict["reasons"])

    doctor = client.post(f"/api/v1/sweeps/{sweep['id']}/diagnoses", json={"max_steps": 1})
    assert doctor.status_code == 201, doctor.text
    assert doctor.json()["kind"] == "diagnose" and doctor.json()["sweep_id"] == sweep["id"]
    report = wait_for(client, f"/api/v1/jobs/{doctor.json()['id']}", "succeeded", "failed", timeout_s=300)
    assert report["status"] == "succeeded", report["error"]
    assert "report.md" in report["links"]["files"]
    bad = client.post(f"/api/v1/sweeps/{sweep['id']}/diagnoses", json={"max_steps": 99})
    assert bad.status_code == 422 and bad.json()["error"]["field"] == "max_steps"


def test_the_recording_of_an_unfinished_or_unknown_sweep_is_refused(client: httpx.Client) -> None:
    assert client.get("/api/v1/sweeps/999999/recording.h5").status_code == 404
    running = client.post("/api/v1/sweeps", json={**SHORT, "duration_s": 300})
    assert running.status_code == 201, running.text
    sweep_id = running.json()["id"]
    wait_until(lambda: client.get(f"/api/v1/sweeps/{sweep_id}").json()["status"] == "running", 60, "running")
    assert client.get(f"/api/v1/sweeps/{sweep_id}/recording.h5").status_code == 409
    client.post(f"/api/v1/sweeps/{sweep_id}/abort")
    wait_for(client, f"/api/v1/sweeps/{sweep_id}", "aborted", "failed", "complete")
