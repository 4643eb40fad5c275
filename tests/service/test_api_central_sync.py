"""A lane (`shockbench serve --database URL`, a real process) keeps testing while its central PostgreSQL
server is stopped and started again: its sweeps and jobs go on in its local store, GET /status shows the
sync backlog and the central database unreachable, the backlog survives the lane's own SIGKILL, and once
the server is back every finished sweep and job is on the central database exactly once, in order, with the
lane's result chain verifiable there. A lane started
while the central database is away starts on its local store and says so in one line, or with
--require-database refuses in one line (exit 2). Each test has a PostgreSQL server of its own to stop."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx
import pytest
import sqlalchemy as sa
from live_server import ROOT, ServeProcess, SimulatedInputs, serve_process, wait_for_status, wait_until
from pg_server import PostgresServer

from daq.formats.vehicle_file import format_vehicle
from service.store.database import Database
from service.store.models import JobRow, SweepRow
from simulators.vehicle_sim import default_quarter_car

KEY = "operator-key-central-sync-01"
LANE = "north"
SWEEP = {"duration_s": 2, "settle_s": 0.5, "vehicle_toml": format_vehicle(default_quarter_car().known)}


def start_lane(tmp_path: Path, url: str, *more: str, name: str = LANE) -> ServeProcess:
    """`serve --database URL` as lane north on tmp_path/data, its output in tmp_path/NAME.log."""
    (tmp_path / "keys.toml").write_text(f'operator = ["{KEY}"]\n')
    args = ("--database", url, "--data", str(tmp_path / "data"), "--keys", str(tmp_path / "keys.toml"))
    return serve_process(tmp_path, name, *args, "--lane", LANE, *more)


def stop_lane(lane: ServeProcess) -> None:
    if lane.process.poll() is None:
        lane.process.send_signal(signal.SIGINT)
        lane.process.wait(60)


def upload(inputs: SimulatedInputs) -> dict[str, bytes]:
    return {"recording": inputs.recording.read_bytes(), "vehicle": inputs.vehicle.read_bytes()}


def succeeded(client: httpx.Client, job_id: int) -> None:
    end = wait_for_status(client, f"/api/v1/jobs/{job_id}", "succeeded", "failed", timeout_s=300)
    assert end["status"] == "succeeded", end["error"]


def sync_status(client: httpx.Client) -> dict[str, Any]:
    sync: dict[str, Any] = client.get("/api/v1/status").json()["sync"]
    return sync


def synced(client: httpx.Client, pushed: int) -> dict[str, Any] | None:
    """The sync status once `pushed` entries are on the central database and none waits."""
    sync = sync_status(client)
    done = sync["reachable"] and sync["pushed"] == pushed and sync["backlog"] == 0
    return sync if done and sync["last_error"] is None else None


def central_jobs(url: str) -> tuple[list[JobRow], list[SweepRow]]:
    central = Database(url)
    try:
        with central.sessions() as session:
            jobs = list(session.scalars(sa.select(JobRow).order_by(JobRow.id)).all())
            sweeps = list(session.scalars(sa.select(SweepRow).order_by(SweepRow.id)).all())
    finally:
        central.dispose()
    return jobs, sweeps


def verify(url: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "service.cli.main", "verify", "--database", url]
    return subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_the_lane_keeps_testing_while_the_central_database_is_stopped(
    tmp_path: Path, own_postgres: PostgresServer, inputs: SimulatedInputs
) -> None:
    server = own_postgres
    url = server.new_database()
    lane = start_lane(tmp_path, url, "--simulated")
    try:
        wait_until(lambda: lane.answers(KEY), 180, "the lane ready")
        with lane.client(KEY) as client:
            fast = {"output_error": "false"}
            first = client.post("/api/v1/jobs", files=upload(inputs), data=fast).json()["id"]
            succeeded(client, first)
            wait_until(lambda: synced(client, 1), 60, "the first job on the central database")

            slow = {"solver": "de", "generations": "800", "output_error": "false"}  # several seconds
            during = client.post("/api/v1/jobs", files=upload(inputs), data=slow).json()["id"]

            def running() -> bool:
                job = client.get(f"/api/v1/jobs/{during}").json()
                assert job["status"] in ("queued", "running"), job
                return job["status"] == "running" and bool((job["progress"] or {}).get("generation"))

            wait_until(running, 120, "the DE job running")
            server.stop()  # the central database is gone, its connections cut
            assert client.get(f"/api/v1/jobs/{during}").json()["status"] == "running"  # in mid-job

            sweep = client.post("/api/v1/sweeps", json=SWEEP)
            assert sweep.status_code == 201, sweep.text
            done = wait_for_status(client, sweep.headers["location"], "complete", "failed", "aborted")
            assert done["status"] == "complete", done
            on_sweep = client.post(done["links"]["jobs"], json={"output_error": False})
            assert on_sweep.status_code == 201, on_sweep.text
            after = client.post("/api/v1/jobs", files=upload(inputs), data=fast).json()["id"]
            local_ids = [first, during, on_sweep.json()["id"], after]
            for job_id in local_ids[1:]:
                succeeded(client, job_id)

            def backlog_waits() -> dict[str, Any] | None:
                sync = sync_status(client)
                return sync if sync["reachable"] is False and sync["backlog"] == 4 else None

            try:
                away = wait_until(backlog_waits, 60, "the backlog of the sweep and three jobs")
            except TimeoutError as exc:
                raise AssertionError(f"{exc}; sync status {sync_status(client)}") from None
            assert away["oldest_pending"] is not None and away["last_error"], away
            print(f"while the central database was away: {away}")

        lane.process.send_signal(signal.SIGKILL)  # the lane dies too before the server is back
        lane.process.wait(30)
        lane = start_lane(tmp_path, url, "--simulated", name="north-again")
        wait_until(lambda: lane.answers(KEY), 180, "the lane ready again")
        with lane.client(KEY) as client:
            wait_until(backlog_waits, 60, "the same backlog after the restart")
            server.start()
            back = wait_until(lambda: synced(client, 4), 120, "the backlog pushed once the server is back")
            assert back["oldest_pending"] is None, back  # pushed: 3 jobs and the sweep
            local = {i: client.get(f"/api/v1/jobs/{i}").json() for i in local_ids}
    finally:
        stop_lane(lane)

    jobs, sweeps = central_jobs(url)
    assert [j.origin_id for j in jobs] == local_ids  # in order, each exactly once
    assert len({j.uid for j in jobs}) == 4
    assert all(j.status == "succeeded" and j.attempts == 1 and j.lane == LANE for j in jobs)
    assert all(local[i]["attempts"] == 1 for i in local_ids)  # none run twice on the lane either
    assert [j.result["masses_kg"] for j in jobs] == [local[i]["result"]["masses_kg"] for i in local_ids]
    assert len(sweeps) == 1 and sweeps[0].status == "complete" and jobs[2].sweep_id == sweeps[0].id
    checked = verify(url)
    assert checked.returncode == 0, checked.stderr
    assert checked.stdout.strip() == "4 results in 1 lane verified, their heads against 4 checkpoints"


def test_a_lane_started_without_its_central_database(
    tmp_path: Path, own_postgres: PostgresServer, inputs: SimulatedInputs
) -> None:
    server = own_postgres
    url = server.new_database()
    server.stop()
    refused = subprocess.run(
        [sys.executable, "-m", "service.cli.serve", "--database", url, "--data", str(tmp_path / "r"),
         "--port", "0", "--require-database"],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert refused.returncode == 2, refused.stderr
    assert refused.stderr.strip().count("\n") == 0 and "--require-database" in refused.stderr
    assert "Traceback" not in refused.stderr

    lane = start_lane(tmp_path, url)
    try:

        def said() -> list[str]:
            starts = "the lane starts on its local store"
            return [line for line in lane.log.read_text().splitlines() if starts in line]

        line = wait_until(said, 60, "the lane saying it starts on its local store")
        assert len(line) == 1 and line[0].startswith("shockbench serve: central database postgresql"), line
        wait_until(lambda: lane.answers(KEY), 180, "the lane ready")
        with lane.client(KEY) as client:
            wait_until(lambda: sync_status(client)["reachable"] is False, 60, "the central database away")
            fast = {"output_error": "false"}
            job_id = client.post("/api/v1/jobs", files=upload(inputs), data=fast).json()["id"]
            succeeded(client, job_id)
            wait_until(lambda: sync_status(client)["backlog"] == 1, 30, "the job waiting to be synced")
            server.start()
            wait_until(lambda: synced(client, 1), 120, "the job pushed once the server is up")
    finally:
        stop_lane(lane)
    jobs, _ = central_jobs(url)
    assert [(j.origin_id, j.status, j.attempts) for j in jobs] == [(job_id, "succeeded", 1)]


@pytest.mark.parametrize("flag", ["--shared-queue", "--require-database"])
def test_the_central_database_flags_need_a_database(tmp_path: Path, flag: str) -> None:
    command = [sys.executable, "-m", "service.cli.serve", "--data", str(tmp_path), "--port", "0", flag]
    refused = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert refused.returncode == 2
    assert (
        refused.stderr.strip()
        == f"shockbench serve: error: {flag} needs --database URL (the central database)"
    )
