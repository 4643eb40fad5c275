"""Two service processes (two lanes) on one real PostgreSQL and one shared data directory: jobs submitted
to either run exactly once on one of them, either answers for every job, and a job whose instance is
killed (SIGKILL) in mid-run is run again by the other once its lease runs out, never by both at once."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
from live_server import ServeProcess, SimulatedInputs, serve_process, wait_for_status, wait_until
from pg_server import PostgresServer

KEY = "operator-key-shared-queue-01"
LEASE_S = 2.0


@pytest.fixture
def lanes(tmp_path: Path, postgres: PostgresServer) -> Iterator[tuple[ServeProcess, ServeProcess]]:
    url = postgres.new_database()
    (tmp_path / "keys.toml").write_text(f'operator = ["{KEY}"]\n')
    # --shared-queue: both lanes run on the central database itself (no local store), sharing its queue
    common = ("--database", url, "--shared-queue", "--data", str(tmp_path / "data"))
    common += ("--keys", str(tmp_path / "keys.toml"))
    north = serve_process(tmp_path, "north", *common, "--lane", "north", "--job-lease-s", str(LEASE_S))
    south = serve_process(tmp_path, "south", *common, "--lane", "south", "--job-lease-s", str(LEASE_S))
    yield north, south
    for lane in (north, south):
        if lane.process.poll() is None:
            lane.process.send_signal(signal.SIGINT)
            lane.process.wait(60)


def upload(inputs: SimulatedInputs) -> dict[str, bytes]:
    return {"recording": inputs.recording.read_bytes(), "vehicle": inputs.vehicle.read_bytes()}


def test_two_lanes_share_the_queue_and_survive_a_kill(
    lanes: tuple[ServeProcess, ServeProcess], inputs: SimulatedInputs
) -> None:
    north, south = lanes
    wait_until(lambda: north.answers(KEY) and south.answers(KEY), 180, "both lanes ready")
    with north.client(KEY) as to_north, south.client(KEY) as to_south:
        ids = [
            (to_north if i % 2 else to_south)
            .post("/api/v1/jobs", files=upload(inputs), data={"output_error": "false"})
            .json()["id"]
            for i in range(6)
        ]
        for job_id in ids:
            done = wait_for_status(to_south, f"/api/v1/jobs/{job_id}", "succeeded", "failed", timeout_s=300)
            assert done["status"] == "succeeded", done["error"]
            assert done["attempts"] == 1 and done["run_by"] in ("north", "south")
            assert to_north.get(f"/api/v1/jobs/{job_id}").json() == done  # either answers for every job
        ran_by = {to_north.get(f"/api/v1/jobs/{i}").json()["run_by"] for i in ids}
        print(f"six jobs ran on: {sorted(ran_by)}")

        slow = {"solver": "de", "generations": "200000", "output_error": "false"}
        job_id = to_north.post("/api/v1/jobs", files=upload(inputs), data=slow).json()["id"]

        def running() -> dict | None:
            job = to_north.get(f"/api/v1/jobs/{job_id}").json()
            return job if job["status"] == "running" and (job["progress"] or {}).get("generation") else None

        first = wait_until(running, 120, "the DE job running")
        victim, survivor = (north, to_south) if first["run_by"] == "north" else (south, to_north)
        other = "south" if first["run_by"] == "north" else "north"
        victim.process.send_signal(signal.SIGKILL)
        victim.process.wait(30)

        def taken_over() -> dict | None:
            job = survivor.get(f"/api/v1/jobs/{job_id}").json()
            assert job["status"] in ("running", "queued"), job
            return job if job["status"] == "running" and job["run_by"] == other else None

        second = wait_until(taken_over, 60, "the other lane running the job")
        assert second["attempts"] == 2
        cancelled = survivor.post(f"/api/v1/jobs/{job_id}/cancel")
        assert cancelled.status_code in (200, 202), cancelled.text
        end = wait_for_status(survivor, f"/api/v1/jobs/{job_id}", "cancelled", "failed", "succeeded")
        assert end["status"] == "cancelled" and end["attempts"] == 2 and end["run_by"] == other
