"""Running the service for tests and benchmarks: in-process, the real uvicorn server on a free loopback
port in a background thread (`LiveServer`); as its own process, `shockbench serve` on a free loopback port
(`serve_process`); a deadline-bounded `wait_until`; and simulated input files (`simulated_inputs`) whose
truth is known.

It lives under tests/ (it was service/api/testing.py): it needs httpx, which only the test extra installs,
so it is no part of the installed product. Benchmarks put tests/service on sys.path to use it."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, TypeVar

import httpx
import numpy as np
from fastapi import FastAPI

from service.api.server import ServiceServer, bind, url_of

T = TypeVar("T")

ROOT = Path(__file__).resolve().parents[2]
SERVE_STARTUP_TIMEOUT_S = 180.0
"""Interpreter, imports, worker and input checker start-up of `serve` on a loaded 2-core machine."""


def wait_until(condition: Callable[[], T | None], timeout_s: float, what: str, poll_s: float = 0.05) -> T:
    """Poll `condition` until it returns something truthy (returned) or the deadline passes (TimeoutError
    naming `what`)."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what}: not within {timeout_s:g} s")
        time.sleep(poll_s)


def wait_for_status(
    client: httpx.Client, path: str, *statuses: str, timeout_s: float = 120
) -> dict[str, Any]:
    """GET `path` (a job, sweep or scheduled test) until its "status" is one of `statuses`; returns it."""

    def reached() -> dict[str, Any] | None:
        item: dict[str, Any] = client.get(path).json()
        return item if item["status"] in statuses else None

    return wait_until(reached, timeout_s, f"{path} {' or '.join(statuses)}")


BROKEN_PATH = "/api/v1/broken"


def add_broken_route(app: FastAPI) -> None:
    """GET BROKEN_PATH raises a RuntimeError with a secret in its message: it stands for any bug a request
    may hit (a 500 that must carry an error id and never the message or a traceback)."""

    def broken() -> None:
        raise RuntimeError("a bug with a secret in its message")

    app.add_api_route(BROKEN_PATH, broken)


def bearer_client(url: str, key: str) -> httpx.Client:
    """An httpx client of the service at `url` sending `key` as its Bearer key."""
    return httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=60)


class LiveServer:
    """`with LiveServer(app) as server:` serves `app` (lifespan included) at `server.url`."""

    def __init__(self, app: FastAPI, startup_timeout_s: float = 60.0) -> None:
        self.app = app
        self._timeout = startup_timeout_s
        self._server: ServiceServer | None = None
        self._thread: threading.Thread | None = None
        self.url = ""

    def __enter__(self) -> LiveServer:
        sock = bind("127.0.0.1", 0)
        self.url = url_of(sock)
        self._server = server = ServiceServer(self.app, log_level="warning")
        self._thread = threading.Thread(
            target=server.run, kwargs={"sockets": [sock]}, name="live-server", daemon=True
        )
        self._thread.start()
        thread = self._thread
        wait_until(lambda: server.started or not thread.is_alive(), self._timeout, "service start-up")
        if not server.started:
            raise RuntimeError("the service did not start (see the log above)")
        return self

    def client(self, key: str) -> httpx.Client:
        """An httpx client of the service sending `key` as its Bearer key."""
        return bearer_client(self.url, key)

    def __exit__(self, *exc_info: object) -> None:
        if self._server is not None and self._thread is not None:
            self._server.stop()
            self._thread.join(timeout=30)


@dataclass
class ServeProcess:
    """`shockbench serve` running as its own process, its stdout and stderr in `log`."""

    process: subprocess.Popen[bytes]
    url: str
    log: Path

    def client(self, key: str) -> httpx.Client:
        """An httpx client of the service sending `key` as its Bearer key."""
        return bearer_client(self.url, key)

    def answers(self, key: str) -> dict[str, Any] | None:
        """GET /status once the service answers with its worker ready, else None (fails if it exited)."""
        assert self.process.poll() is None, f"serve exited:\n{self.log.read_text()}"
        try:
            with self.client(key) as client:
                status: dict[str, Any] = client.get("/api/v1/status", timeout=5).json()
        except httpx.TransportError:
            return None
        return status if status["worker"]["ready"] else None

    def terminate(self) -> int:
        """Stop it as a lane's service manager does (SIGTERM), wait for its graceful shutdown and return
        its exit code. A killed service leaves its worker's semaphores to multiprocessing's resource
        tracker, which then warns on the shared stderr in its own format; a terminated one releases them."""
        self.process.send_signal(signal.SIGTERM)
        return self.process.wait(60)

    def stop(self) -> None:
        """Kill it if it still runs."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(30)


def serve_process(folder: Path, name: str, *args: str) -> ServeProcess:
    """Start `python -m service.cli.serve --port 0 ARGS` (from the repository's root, its output in
    folder/NAME.log) and wait until it says which URL it listens on."""
    log = folder / f"{name}.log"
    command = [sys.executable, "-m", "service.cli.serve", "--port", "0", *args]
    with log.open("w") as out:
        process = subprocess.Popen(command, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT)

    def listening() -> str | None:
        assert process.poll() is None, f"serve exited early:\n{log.read_text()}"
        match = re.search(r"listening on (http://\S+)", log.read_text())
        return match.group(1) if match else None

    try:
        url = wait_until(listening, SERVE_STARTUP_TIMEOUT_S, "serve listening", 0.1)
    except BaseException:
        process.kill()
        process.wait(30)
        raise
    return ServeProcess(process, url, log)


@dataclass(frozen=True)
class SimulatedInputs:
    recording: Path
    vehicle: Path
    true_curve: Callable[[np.ndarray], np.ndarray]
    """Velocity (m/s) -> force (N) of the simulated damper."""
    suspension_velocity_m_s: np.ndarray
    """Noise-free ẋ_s − ẋ_t at the samples: the excited velocity range."""


@cache
def _simulated(seconds: float, seed: int) -> tuple[str, str, Callable, np.ndarray]:
    from daq.formats.recording_csv import write_recording_csv
    from daq.formats.vehicle_file import format_vehicle
    from estimator.sweep import SweepSettings
    from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate, true_damper

    vehicle = default_quarter_car()
    sim = simulate(vehicle, SimulationSettings(sweep=SweepSettings(duration_s=seconds), seed=seed))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "recording.csv"
        write_recording_csv(path, sim.recording)
        csv_text = path.read_text()
    velocity = sim.truth_states[:, 1] - sim.truth_states[:, 3]
    return csv_text, format_vehicle(vehicle.known), true_damper(vehicle.dampers[0]).force, velocity


def simulated_inputs(folder: Path, seconds: float = 6.0, seed: int = 1) -> SimulatedInputs:
    """A quarter-car recording CSV and its vehicle file from the physics simulator (embedded default car,
    valve-model damper, 5 µm sensor noise), with the truth to compare against. Simulated once per
    process for each (seconds, seed): a sweep takes seconds to integrate."""
    csv_text, vehicle_text, truth, velocity = _simulated(seconds, seed)
    folder.mkdir(parents=True, exist_ok=True)
    recording, vehicle_file = folder / f"sim-{seconds:g}s-{seed}.csv", folder / "vehicle.toml"
    recording.write_text(csv_text)
    vehicle_file.write_text(vehicle_text)
    return SimulatedInputs(recording, vehicle_file, truth, velocity)
