"""End to end: `shockbench serve` as its own process (real uvicorn on loopback, a free port), driven with
httpx like the operator UI: upload a simulated recording -> identification job -> the curve within 3% of
the simulator's truth; the service prints its generated operator key and stops cleanly with its worker."""

from __future__ import annotations

import queue
import re
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from live_server import SimulatedInputs, simulated_inputs, wait_until

from estimator.damper import PiecewiseLinearCurve

CURVE_TOLERANCE_PERCENT = 3.0
MASS_TOLERANCE_PERCENT = 3.0
TRUE_SPRUNG_MASS_KG = 375.0  # simulators.vehicle_sim.default_quarter_car


class Service:
    """`python -m service.cli.serve` in a subprocess, its stdout read line by line."""

    def __init__(self, data_dir: Path) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "service.cli.serve", "--port", "0", "--data", str(data_dir)],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.output: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.put(line)

    def printed(self, pattern: str) -> re.Match[str] | None:
        while not self.lines.empty():
            self.output.append(self.lines.get())
        if self.process.poll() is not None and self.lines.empty():
            raise RuntimeError("the service exited:\n" + "".join(self.output))
        return next((m for line in self.output if (m := re.search(pattern, line))), None)


@pytest.fixture
def service(tmp_path: Path) -> Iterator[Service]:
    service = Service(tmp_path / "data")
    try:
        yield service
    finally:
        if service.process.poll() is None:
            service.process.kill()
            service.process.wait(30)


def test_simulated_recording_to_a_curve_within_3_percent_of_the_truth(
    service: Service, tmp_path: Path
) -> None:
    inputs: SimulatedInputs = simulated_inputs(tmp_path / "inputs", seconds=6.0, seed=1)
    url = wait_until(lambda: service.printed(r"listening on (http://127\.0\.0\.1:\d+)"), 60, "URL").group(1)
    key = wait_until(lambda: service.printed(r"^    (\S{16,})$"), 60, "generated key").group(1)

    with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=30) as client:
        wait_until(lambda: client.get("/api/v1/status").status_code == 200, 60, "service answering")
        files = {
            "recording": ("recording.csv", inputs.recording.read_bytes(), "text/csv"),
            "vehicle": ("vehicle.toml", inputs.vehicle.read_bytes(), "application/toml"),
        }
        submitted = client.post("/api/v1/jobs", files=files)
        assert submitted.status_code == 201, submitted.text
        location = submitted.headers["location"]
        job = wait_until(
            lambda: (j := client.get(location).json())["status"] in ("succeeded", "failed") and j, 180, "job"
        )
        assert job["status"] == "succeeded", job["error"]
        worker_pid = client.get("/api/v1/status").json()["worker"]["pid"]

    curve = job["result"]["curves"][0]
    identified = PiecewiseLinearCurve(np.array(curve["velocity_m_s"]), np.array(curve["force_N"]))
    lo, hi = np.quantile(inputs.suspension_velocity_m_s, [0.005, 0.995])
    grid = np.linspace(lo, hi, 400)
    truth = inputs.true_curve(grid)
    error = 100 * np.sqrt(np.mean((identified.force(grid) - truth) ** 2)) / np.max(np.abs(truth))
    assert error <= CURVE_TOLERANCE_PERCENT, f"curve error {error:.2f}% of peak force"
    mass_error = 100 * abs(job["result"]["masses_kg"]["sprung"] / TRUE_SPRUNG_MASS_KG - 1)
    assert mass_error <= MASS_TOLERANCE_PERCENT

    service.process.send_signal(signal.SIGINT)
    assert service.process.wait(60) == 0
    assert not Path(f"/proc/{worker_pid}").exists() or _is_zombie(worker_pid)
    assert "Traceback" not in "".join(service.output)


def _is_zombie(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1].startswith("Z")
    except OSError:
        return True
