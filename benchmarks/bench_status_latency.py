"""Benchmark: latency of GET /api/v1/status, idle and while a DE identification job runs, side by side.

    .venv/bin/python benchmarks/bench_status_latency.py                  # paper DE settings
    .venv/bin/python benchmarks/bench_status_latency.py --requests 500   # fewer idle calls

`python -m service.cli.serve` runs in its own process on loopback (port 0, a keys file, a fresh data
directory). This process simulates the embedded default quarter car (20 s sweep 0-20 Hz ±4 mm, 5 µm
noise), then with one keep-alive httpx client calls GET /api/v1/status back to back: first `--requests`
times with the service idle, then while a DE job runs (solver de with the paper's settings: F 1, CR 0.3,
NP 70, 3000 generations; followed by the output-error simulation and the plots), until it finishes.
Each call is timed from request to parsed response; the status body says whether a job ran and in which
stage, so the samples are split by what the worker was doing. Target of the issue: p99 under 50 ms
while a DE job runs. For reference the same job is first run without status calls: back-to-back calls
keep a core busy in this client and most of one in the service, which the job then lacks.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

from daq.formats.recording_csv import write_recording_csv
from daq.formats.vehicle_file import write_vehicle
from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "service"))

from live_server import wait_until  # the tests' deadline-bounded wait, shared

KEY = "benchmark-operator-key-0123456789"
TARGET_P99_MS = 50.0


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, round(q / 100 * len(ordered) + 0.5) - 1))]


def row(label: str, samples: list[float]) -> str:
    if not samples:
        return f"| {label} | 0 | - | - | - | - |"
    ms = [s * 1e3 for s in samples]
    return (
        f"| {label} | {len(ms)} | {statistics.median(ms):.2f} | {percentile(ms, 99):.2f} | "
        f"{max(ms):.2f} | {statistics.fmean(ms):.2f} |"
    )


def start_service(folder: Path, worker_nice: int) -> tuple[subprocess.Popen[str], str]:
    keys = folder / "keys.toml"
    keys.write_text(f'operator = ["{KEY}"]\n')
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "service.cli.serve",
            "--port",
            "0",
            "--data",
            str(folder / "data"),
            "--keys",
            str(keys),
            "--log-level",
            "warning",
            "--worker-nice",
            str(worker_nice),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    for line in process.stdout:  # the first line names the URL
        match = re.search(r"listening on (http://\S+)", line)
        if match:
            return process, match.group(1)
    raise RuntimeError(f"the service exited with {process.wait()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=2000, help="idle status calls (default 2000)")
    parser.add_argument("--generations", type=int, default=3000, help="DE generations (default 3000)")
    parser.add_argument("--worker-nice", type=int, default=5, help="the service's --worker-nice (default 5)")
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.2f} at start"
    )
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        vehicle = default_quarter_car()
        recording = simulate(vehicle, SimulationSettings(seed=0)).recording
        write_recording_csv(folder / "recording.csv", recording)
        write_vehicle(folder / "vehicle.toml", vehicle.known)
        process, url = start_service(folder, args.worker_nice)
        try:
            with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {KEY}"}, timeout=10) as client:
                wait_until(
                    lambda: client.get("/api/v1/status").json()["worker"]["ready"], 120, "worker ready", 0.2
                )
                idle = [timed_status(client)[0] for _ in range(args.requests)]
                files = {
                    "recording": (folder / "recording.csv").read_bytes(),
                    "vehicle": (folder / "vehicle.toml").read_bytes(),
                }
                data = {"solver": "de", "generations": str(args.generations)}
                alone = time.perf_counter()
                reference = client.post("/api/v1/jobs", files=files, data=data).json()
                wait_until(
                    lambda: client.get(f"/api/v1/jobs/{reference['id']}").json()["status"] == "succeeded",
                    600,
                    "reference job",
                    0.5,
                )
                alone = time.perf_counter() - alone
                job = client.post("/api/v1/jobs", files=files, data=data).json()
                by_stage: dict[str, list[float]] = {}
                started = time.perf_counter()
                while True:
                    elapsed, body = timed_status(client)
                    current = body["current_job"]
                    if current is None and body["queue_length"] == 0:
                        break
                    stage = (current or {}).get("progress") or {}
                    by_stage.setdefault(stage.get("stage", "queued"), []).append(elapsed)
                wall = time.perf_counter() - started
                final = client.get(f"/api/v1/jobs/{job['id']}").json()
        finally:
            process.send_signal(signal.SIGINT)
            process.wait(60)
    running = [s for stage, samples in by_stage.items() if stage != "queued" for s in samples]
    de = by_stage.get("differential evolution", [])
    print(
        f"\njob {final['id']}: {final['status']}, DE {final['progress']['generation']} generations "
        f"(F 1, CR 0.3, NP 70), worker nice +{args.worker_nice}: {wall:.1f} s wall while status was called "
        f"back to back by one keep-alive client ({alone:.1f} s for the same job without status calls)\n"
    )
    print("| GET /api/v1/status | calls | p50 (ms) | p99 (ms) | max (ms) | mean (ms) |")
    print("|---|---:|---:|---:|---:|---:|")
    print(row("idle", idle))
    print(row("while the DE job runs (DE stage)", de))
    print(row("while the job runs (any stage)", running))
    p99 = percentile([s * 1e3 for s in running], 99) if running else float("nan")
    print(
        f"\np99 while the job runs {p99:.2f} ms; target < {TARGET_P99_MS:g} ms: "
        f"{'met' if p99 < TARGET_P99_MS else 'NOT met'}"
    )


def timed_status(client: httpx.Client) -> tuple[float, dict]:
    start = time.perf_counter()
    response = client.get("/api/v1/status")
    body = response.json()
    elapsed = time.perf_counter() - start
    response.raise_for_status()
    return elapsed, body


if __name__ == "__main__":
    main()
