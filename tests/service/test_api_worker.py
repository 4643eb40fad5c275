"""The worker process: killed mid-job, that job is marked failed with the reason and the next job runs on
a restarted worker; progress reports are throttled and carry an ETA."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from live_server import LiveServer, SimulatedInputs, wait_until

from estimator.solvers.differential_evolution import DEProgress
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.jobs.context import ProgressReporter
from service.jobs.messages import Progress
from service.jobs.process import describe_exit

OPERATOR = "operator-key-0123456789"
AUTH = {"Authorization": f"Bearer {OPERATOR}"}


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    settings = ServiceSettings(
        data_dir=tmp_path_factory.mktemp("worker"), keys=KeyRing({OPERATOR: Role.OPERATOR})
    )
    with LiveServer(create_app(settings)) as server, httpx.Client(base_url=server.url, headers=AUTH) as c:
        yield c


def submit(client: httpx.Client, inputs: SimulatedInputs, **options: str) -> dict[str, Any]:
    files = {"recording": inputs.recording.read_bytes(), "vehicle": inputs.vehicle.read_bytes()}
    response = client.post("/api/v1/jobs", files=files, data=options)
    assert response.status_code == 201, response.text
    return response.json()


def job(client: httpx.Client, job_id: int) -> dict[str, Any]:
    return client.get(f"/api/v1/jobs/{job_id}").json()


def status(client: httpx.Client) -> dict[str, Any]:
    return client.get("/api/v1/status").json()


def test_killing_the_worker_mid_job_fails_that_job_and_the_next_job_runs(
    client: httpx.Client, inputs: SimulatedInputs
) -> None:
    victim = submit(client, inputs, solver="de", generations="200000", output_error="false")
    following = submit(client, inputs, output_error="false")
    wait_until(lambda: (job(client, victim["id"])["progress"] or {}).get("generation"), 120, "DE running")
    before = status(client)
    assert before["current_job"]["id"] == victim["id"] and before["queue_length"] == 1

    os.kill(before["worker"]["pid"], signal.SIGKILL)

    failed = wait_until(
        lambda: (j := job(client, victim["id"]))["status"] == "failed" and j, 60, "victim failed"
    )
    assert failed["error"] == (
        "the worker process died while the job ran (killed by SIGKILL); the worker was restarted"
    )
    assert failed["progress"]["generation"] >= 1 and failed["finished_at"] is not None
    done = wait_until(
        lambda: (j := job(client, following["id"]))["status"] in ("succeeded", "failed") and j,
        120,
        "next job",
    )
    assert done["status"] == "succeeded", done["error"]
    after = status(client)
    assert after["worker"]["alive"] and after["worker"]["pid"] != before["worker"]["pid"]
    assert after["worker"]["restarts"] == before["worker"]["restarts"] + 1
    assert after["current_job"] is None and after["queue_length"] == 0


def test_a_worker_that_dies_while_idle_is_restarted(client: httpx.Client) -> None:
    before = status(client)["worker"]
    os.kill(before["pid"], signal.SIGKILL)
    after = wait_until(
        lambda: (w := status(client)["worker"])["restarts"] > before["restarts"] and w["alive"] and w,
        60,
        "worker restarted",
    )
    assert after["pid"] != before["pid"]


def test_exit_descriptions() -> None:
    assert describe_exit(-signal.SIGKILL) == "killed by SIGKILL"
    assert describe_exit(1) == "exit code 1"
    assert describe_exit(None) == "exit status unknown"


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_progress_is_throttled_and_estimates_the_time_left() -> None:
    sent: list[Progress] = []
    clock = FakeClock()
    reporter = ProgressReporter(sent.append, min_interval_s=0.5, clock=clock)
    reporter.stage("differential evolution")
    for generation in range(1, 101):  # 10 ms per generation
        clock.now += 0.01
        reporter.generation(DEProgress(generation, 100, 1000.0 / generation, generation * 70))
    reporter.stage("plotting")
    generations = [p.generation for p in sent if p.stage == "differential evolution" and p.generation]
    assert generations[0] == 1 and generations[-1] == 100  # first and last always
    assert len(generations) <= 100 * 0.01 / 0.5 + 2  # at most one every 0.5 s in between
    middle = next(p for p in sent if p.generation and 1 < p.generation < 100)
    assert middle.eta_s == pytest.approx((100 - middle.generation) * 0.01)
    assert sent[-1].stage == "plotting" and sent[-1].generation == 100 and sent[-1].eta_s is None
    assert sent[-1].best_objective == pytest.approx(10.0)
