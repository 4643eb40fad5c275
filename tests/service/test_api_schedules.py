"""Scheduled inspection-line tests through the API on the real server with the in-process simulated bench:
admin only, checked at submit, run one at a time when due (the scheduler's clock is moved by hand, never
waited for), each ending with its sweep and an identification job; waiting for an operator's sweep to free
the lane; cancelling; and a restart that keeps waiting tests and fails the one a shutdown cut off."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest
from live_server import LiveServer, wait_until
from live_server import wait_for_status as wait_for

from daq.formats.vehicle_file import format_vehicle
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.scheduler import InspectionScheduler
from simulators.vehicle_sim import default_quarter_car

ADMIN = "admin-key-0123456789"
OPERATOR = "operator-key-0123456789"
VIEWER = "viewer-key-0123456789"
KEYS = KeyRing({ADMIN: Role.ADMIN, OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER})
VEHICLE_TOML = format_vehicle(default_quarter_car().known)
FAST_JOB = {"output_error": False}
TEST = {"duration_s": 2, "settle_s": 0.5, "vehicle_toml": VEHICLE_TOML, "job": FAST_JOB}
LONG = {"duration_s": 300, "settle_s": 0.5, "vehicle_toml": VEHICLE_TOML}  # the envelope's longest
"""A sweep that runs for minutes on the simulated clock: something to abort."""
ENDED = ("done", "failed", "cancelled")


def settings_in(folder: Path) -> ServiceSettings:
    return ServiceSettings(data_dir=folder, keys=KEYS, simulated=True)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    with LiveServer(create_app(settings_in(tmp_path_factory.mktemp("schedules")))) as s:
        yield s


def client_of(server: LiveServer, key: str = ADMIN) -> httpx.Client:
    return httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {key}"}, timeout=60)


@pytest.fixture
def admin(server: LiveServer) -> Iterator[httpx.Client]:
    with client_of(server) as c:
        yield c


def scheduler_of(server: LiveServer) -> InspectionScheduler:
    scheduler = server.app.state.services.scheduler
    assert scheduler is not None
    return scheduler


def one_pass(server: LiveServer) -> None:
    """Wake the scheduler and wait until it has completed a pass that began after now."""
    scheduler = scheduler_of(server)
    before = scheduler.passes
    scheduler.wake()
    wait_until(lambda: scheduler.passes >= before + 2, 60, "a scheduler pass")


def schedule(client: httpx.Client, body: dict[str, Any]) -> dict[str, Any]:
    response = client.post("/api/v1/schedules", json=body)
    assert response.status_code == 201, response.text
    test = response.json()
    assert response.headers["location"] == test["links"]["self"] == f"/api/v1/schedules/{test['id']}"
    return test


def later(days: float) -> str:
    return (datetime.now(UTC) + timedelta(days=days)).isoformat()


@pytest.mark.parametrize(
    ("method", "path"), [("POST", "/api/v1/schedules"), ("POST", "/api/v1/schedules/1/cancel")]
)
def test_schedules_need_an_admin(server: LiveServer, method: str, path: str) -> None:
    anonymous = httpx.request(method, server.url + path, json=TEST)
    assert anonymous.status_code == 401, anonymous.text
    for key in (VIEWER, OPERATOR):
        with client_of(server, key) as c:
            refused = c.request(method, path, json=TEST)
            assert refused.status_code == 403, refused.text
            assert "admin role" in refused.json()["error"]["message"]
    with client_of(server, VIEWER) as viewer:
        assert viewer.get("/api/v1/schedules").status_code == 200


def test_a_test_is_checked_at_submit(admin: httpx.Client) -> None:
    before = admin.get("/api/v1/schedules").json()["total"]
    cases = [
        ({**TEST, "amplitude_m": 0.01}, "amplitude_m"),
        ({**TEST, "vehicle_toml": "[vehicle\nmodel = 1"}, "vehicle_toml"),
        ({**TEST, "run_at": "2026-11-23T06:30:00"}, "run_at"),  # no zone: ambiguous on a line
        ({**TEST, "job": {"model": "axle"}}, "job.model"),
        ({**TEST, "job": {"points": 500}}, "job.points"),
        ({**TEST, "when": "now"}, "when"),
    ]
    for body, field in cases:
        response = admin.post("/api/v1/schedules", json=body)
        assert response.status_code == 422, (field, response.text)
        assert response.json()["error"]["field"] == field, response.json()
    assert admin.get("/api/v1/schedules").json()["total"] == before, "a refused test was stored"


def test_due_tests_run_one_at_a_time_each_with_its_sweep_and_job(
    server: LiveServer, admin: httpx.Client
) -> None:
    timed = schedule(admin, {**TEST, "run_at": later(days=1)})
    first = schedule(admin, TEST)
    second = schedule(admin, {**TEST, "amplitude_m": 0.003})
    assert timed["status"] == first["status"] == "waiting" and first["created_by"]

    done = [wait_for(admin, t["links"]["self"], *ENDED) for t in (first, second)]
    for test in done:
        assert test["status"] == "done", test
        assert test["sweep_id"] and test["job_id"] and test["reason"] is None
    sweeps = [admin.get(t["links"]["sweep"]).json() for t in done]
    assert [s["status"] for s in sweeps] == ["complete", "complete"]
    assert sweeps[1]["settings"]["amplitude_m"] == 0.003
    assert sweeps[0]["finished_at"] <= sweeps[1]["started_at"], "two tests ran at once on one bench"
    assert sweeps[0]["operator"] == first["created_by"], "the sweep does not say who scheduled it"

    job = wait_for(admin, done[0]["links"]["job"], "succeeded", "failed", "cancelled", timeout_s=300)
    assert job["status"] == "succeeded", job["error"]
    assert job["input_source"] == "sweep" and job["sweep_id"] == sweeps[0]["id"]
    assert job["options"]["output_error"] is False, "the test's job options were not used"
    assert job["result"]["curves"][0]["force_N"]

    one_pass(server)
    assert admin.get(timed["links"]["self"]).json()["status"] == "waiting", "ran before its time"
    cancelled = admin.post(timed["links"]["cancel"])
    assert cancelled.status_code == 200 and cancelled.json()["status"] == "cancelled"
    assert admin.post(timed["links"]["cancel"]).status_code == 409
    listed = admin.get("/api/v1/schedules", params={"status": "done"}).json()
    assert {first["id"], second["id"]} <= {t["id"] for t in listed["tests"]}


def test_a_timed_test_waits_for_its_time_then_for_a_free_lane(
    server: LiveServer, admin: httpx.Client
) -> None:
    scheduler = scheduler_of(server)
    run_at = datetime.now(UTC) + timedelta(days=2)
    test = schedule(admin, {**TEST, "run_at": run_at.isoformat()})

    with client_of(server, OPERATOR) as operator:
        response = operator.post("/api/v1/sweeps", json=LONG)
        assert response.status_code == 201, response.text
        operators_sweep = response.json()
        try:
            scheduler.clock = lambda: run_at + timedelta(minutes=1)
            one_pass(server)
            now = admin.get(test["links"]["self"]).json()
            assert now["status"] == "waiting" and now["sweep_id"] is None, "took a busy lane"
            assert operator.post(operators_sweep["links"]["abort"]).status_code == 202
            # the operator's sweep ending wakes the scheduler: no pass needs to be asked for
            finished = wait_for(admin, test["links"]["self"], *ENDED)
        finally:
            scheduler.clock = lambda: datetime.now(UTC)
    assert finished["status"] == "done", finished
    sweep = admin.get(finished["links"]["sweep"]).json()
    aborted = admin.get(operators_sweep["links"]["self"]).json()
    assert aborted["status"] == "aborted" and aborted["finished_at"] <= sweep["started_at"]


def test_a_restart_keeps_waiting_tests_and_fails_the_one_it_cut_off(tmp_path: Path) -> None:
    with LiveServer(create_app(settings_in(tmp_path))) as first, client_of(first) as admin:
        waiting = schedule(admin, {**TEST, "run_at": later(days=3)})
        cut_off = schedule(admin, {**LONG, "job": FAST_JOB})
        running = wait_for(admin, cut_off["links"]["self"], "running", *ENDED)
        assert running["status"] == "running"
        wait_until(lambda: admin.get(cut_off["links"]["self"]).json()["sweep_id"], 60, "its sweep")
    # shutting down stopped the running sweep (recording kept, the sweep failed "service stopped"); the
    # test itself was left running

    with LiveServer(create_app(settings_in(tmp_path))) as second, client_of(second) as admin:
        ended = wait_for(admin, cut_off["links"]["self"], *ENDED)
        assert ended["status"] == "failed" and ended["job_id"] is None
        assert ended["reason"] == f"sweep {ended['sweep_id']} failed: service stopped", ended["reason"]
        kept = admin.get(waiting["links"]["self"]).json()
        assert kept["status"] == "waiting" and kept["run_at"] == waiting["run_at"]
        assert kept["sweep_settings"] == waiting["sweep_settings"]
