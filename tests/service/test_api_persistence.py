"""Persistence: restarting the server keeps all jobs and results; jobs cut off by a crash are marked
failed with the reason, queued ones are resumed; state changes have exactly one winner."""

from __future__ import annotations

import shutil
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
import sqlalchemy as sa
from live_server import LiveServer, SimulatedInputs, wait_for_status, wait_until

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.server import SHUTDOWN_GRACE_S
from service.store import Database, JobStatus, JobStore
from service.store.job_queue import DEFAULT_MAX_ATTEMPTS
from service.store.jobs import RESTART_REASON, JobFiles
from service.store.models import JobRow

OPERATOR = "operator-key-0123456789"
AUTH = {"Authorization": f"Bearer {OPERATOR}"}


def settings_for(data_dir: Path, database_url: str | None = None) -> ServiceSettings:
    return ServiceSettings(
        data_dir=data_dir, keys=KeyRing({OPERATOR: Role.OPERATOR}), database_url=database_url
    )


def finished(client: httpx.Client, job_id: int, timeout_s: float = 120) -> dict[str, Any]:
    return wait_for_status(
        client, f"/api/v1/jobs/{job_id}", "succeeded", "failed", "cancelled", timeout_s=timeout_s
    )


def upload(inputs: SimulatedInputs) -> dict[str, bytes]:
    return {"recording": inputs.recording.read_bytes(), "vehicle": inputs.vehicle.read_bytes()}


def test_restarting_the_server_keeps_all_jobs_and_results(
    tmp_path: Path, inputs: SimulatedInputs, database_url: str
) -> None:
    with (
        LiveServer(create_app(settings_for(tmp_path, database_url))) as server,
        httpx.Client(base_url=server.url, headers=AUTH) as client,
    ):
        succeeded = client.post("/api/v1/jobs", files=upload(inputs), data={"output_error": "false"}).json()
        cancelled = client.post("/api/v1/jobs", files=upload(inputs), data={"points": "8"}).json()
        client.post(f"/api/v1/jobs/{cancelled['id']}/cancel")
        before = {j: finished(client, j) for j in (succeeded["id"], cancelled["id"])}
        plot = client.get(f"/api/v1/jobs/{succeeded['id']}/plot.svg").content
    assert before[succeeded["id"]]["status"] == "succeeded"

    with (
        LiveServer(create_app(settings_for(tmp_path, database_url))) as server,
        httpx.Client(base_url=server.url, headers=AUTH) as client,
    ):
        after = {j: client.get(f"/api/v1/jobs/{j}").json() for j in before}
        assert after == before
        assert client.get(f"/api/v1/jobs/{succeeded['id']}/plot.svg").content == plot
        assert client.get("/api/v1/jobs").json()["total"] == 2


def test_after_a_crash_running_jobs_run_again_until_they_have_had_their_tries(
    tmp_path: Path, inputs: SimulatedInputs
) -> None:
    """The database as a crashed service leaves it: one job running (its first try), one running for the
    third time (it took the service down twice before), one queued."""
    settings = settings_for(tmp_path)
    database = Database(settings.resolved_database_url)
    database.upgrade_schema()
    store = JobStore(database)

    def place(job_id: int) -> JobFiles:
        folder = tmp_path / f"job{job_id}"
        folder.mkdir()
        shutil.copy(inputs.recording, folder / "recording.csv")
        shutil.copy(inputs.vehicle, folder / "vehicle.toml")
        return JobFiles(folder / "recording.csv", folder / "vehicle.toml", folder)

    lane = settings.lane
    cut_off = store.create("identify", {"output_error": False}, place)
    assert store.mark_running(cut_off.id, owner=lane)
    poison = store.create("identify", {"output_error": False}, place)
    for _ in range(DEFAULT_MAX_ATTEMPTS):
        assert store.mark_running(poison.id, owner=lane)
        if _ < DEFAULT_MAX_ATTEMPTS - 1:
            with database.transaction() as session:  # cut off again: back to queued, the try counted
                session.execute(sa.update(JobRow).where(JobRow.id == poison.id).values(status="queued"))
    waiting = store.create("identify", {"output_error": False}, place)
    database.dispose()

    with (
        LiveServer(create_app(settings)) as server,
        httpx.Client(base_url=server.url, headers=AUTH) as client,
    ):
        failed = client.get(f"/api/v1/jobs/{poison.id}").json()
        assert failed["status"] == "failed" and failed["error"] == RESTART_REASON
        again = finished(client, cut_off.id)
        assert again["status"] == "succeeded", again["error"]
        resumed = finished(client, waiting.id)
        assert resumed["status"] == "succeeded", resumed["error"]
    database = Database(settings.resolved_database_url)
    try:
        assert JobStore(database).get(cut_off.id).attempts == 2  # type: ignore[union-attr]
    finally:
        database.dispose()


def test_stopping_the_server_puts_the_running_job_back_in_the_queue_and_ends_event_streams(
    tmp_path: Path, inputs: SimulatedInputs
) -> None:
    settings = settings_for(tmp_path)
    lines: list[str] = []
    with (
        LiveServer(create_app(settings)) as server,
        httpx.Client(base_url=server.url, headers=AUTH) as client,
    ):
        data = {"solver": "de", "generations": "200000", "output_error": "false"}
        job = client.post("/api/v1/jobs", files=upload(inputs), data=data).json()
        wait_until(
            lambda: (client.get(f"/api/v1/jobs/{job['id']}").json()["progress"] or {}).get("generation"),
            120,
            "DE running",
        )

        def listen() -> None:
            with (
                httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as c,
                c.stream("GET", f"/api/v1/jobs/{job['id']}/events") as response,
            ):
                lines.extend(response.iter_lines())

        listener = threading.Thread(target=listen)
        listener.start()
        wait_until(lambda: server.app.state.services.manager.broker.listeners(job["id"]), 30, "stream open")
        stopping = time.monotonic()
    listener.join(30)
    assert not listener.is_alive()
    assert "event: closing" in lines  # the stream ended because the service stopped, not by a timeout
    assert time.monotonic() - stopping < SHUTDOWN_GRACE_S
    database = Database(settings.resolved_database_url)
    try:
        record = JobStore(database).get(job["id"])
    finally:
        database.dispose()
    assert record is not None and record.status is JobStatus.QUEUED and record.started_at is None


def test_state_changes_have_one_winner(tmp_path: Path, database_url: str) -> None:
    database = Database(database_url)
    database.upgrade_schema()
    store = JobStore(database)
    files = JobFiles(tmp_path / "r.csv", tmp_path / "v.toml", tmp_path)
    job = store.create("identify", {}, lambda _id: files, submitted_by="abc")
    assert job.status is JobStatus.QUEUED and job.submitted_by == "abc"
    assert store.cancel(job.id)
    assert not store.mark_running(job.id)  # cancelled first: it never runs
    assert not store.succeed(job.id, {"x": 1}, {}, None)
    other = store.create("identify", {}, lambda _id: files)
    assert store.mark_running(other.id)
    assert not store.cancel(other.id)  # a running job is cancelled through its worker, not here
    assert store.succeed(other.id, {"x": 1}, {"plot.png": "plot.png"}, {"stage": "done", "elapsed_s": 1.0})
    assert not store.fail(other.id, "late")
    assert store.get(other.id).result == {"x": 1}
    assert store.queued_ids() == []
    records, total = store.list_jobs(status=JobStatus.SUCCEEDED)
    assert total == 1 and records[0].id == other.id
    database.dispose()


def test_a_job_whose_input_cannot_be_placed_is_not_created(tmp_path: Path, database_url: str) -> None:
    database = Database(database_url)
    database.upgrade_schema()
    store = JobStore(database)

    def refuse(_job_id: int) -> JobFiles:
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        store.create("identify", {}, refuse)
    assert store.list_jobs() == ([], 0)
    database.dispose()
