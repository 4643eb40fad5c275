"""Benchmark: GET /status and GET /jobs latency while a 60 MB upload, a DE job and a sweep run at once.

    .venv/bin/python benchmarks/bench_service_under_load.py
    .venv/bin/python benchmarks/bench_service_under_load.py --upload-mb 60 --generations 3000

Processes besides this one: `shockbench sim-devices` (a simulated bench on real transports, on the wall
clock), `python -m service.cli.serve --config` on it (port 0, a keys file, a fresh data directory), the
service's worker and input checker, and curl for the upload. This process writes a 20 s simulated
recording (the DE job's input) and a valid recording CSV of `--upload-mb` MB (1 kHz, quarter car), then:

1. calls GET /api/v1/status and GET /api/v1/jobs `--idle-requests` times each with nothing running (the
   machine's baseline at that moment);
2. submits the DE job (solver de, the paper's settings) and starts a 20 s sweep on the bench;
3. uploads the large CSV with curl, another process (an identification job, output_error false);
4. meanwhile calls GET /api/v1/status and GET /api/v1/jobs alternately, back to back, on one keep-alive
   client, and labels every call with what was going on: upload in flight, DE job running, sweep running.

Targets of issue 14: GET /status p99 < 50 ms and max < 300 ms, GET /jobs p99 < 50 ms, while all three run.
The machine is shared with other work: state the load average with the figures.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from daq.formats.recording_csv import read_recording_csv, write_recording_csv
from daq.formats.vehicle_file import format_vehicle, write_vehicle
from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "service"))

from live_server import wait_until  # the tests' deadline-bounded wait, shared
from realtime_bench import realtime_service

KEY = "benchmark-operator-key-0123456789"
PATHS = ("/api/v1/status", "/api/v1/jobs")
TARGET_P99_MS = 50.0
TARGET_MAX_MS = 300.0


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, round(q / 100 * len(ordered) + 0.5) - 1))]


def row(label: str, samples: list[float]) -> str:
    if not samples:
        return f"| {label} | 0 | - | - | - |"
    ms = [s * 1e3 for s in samples]
    return f"| {label} | {len(ms)} | {statistics.median(ms):.1f} | {percentile(ms, 99):.1f} | {max(ms):.1f} |"


def write_large_csv(path: Path, megabytes: float, source: Path) -> None:
    """A valid quarter-car recording CSV of about `megabytes` MB: the simulated sweep's samples repeated
    on a continuing 1 ms grid."""
    recording = read_recording_csv(source)
    data = np.column_stack([recording.time_s, *(recording.channels[c] for c in ("x_s", "x_t", "x_r"))])
    rows = int(megabytes * 1e6 / 61)  # ~61 bytes a row as write_recording_csv prints them
    values = np.tile(data[:, 1:], (rows // len(data) + 1, 1))[:rows]
    with path.open("w") as out:
        out.write("t,x_s,x_t,x_r\n")
        np.savetxt(
            out, np.column_stack([np.arange(rows) * 1e-3, values]), delimiter=",", fmt=["%.6f"] + ["%.9e"] * 3
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--upload-mb", type=float, default=60.0, help="size of the upload (default 60)")
    parser.add_argument("--generations", type=int, default=3000, help="DE generations (default 3000)")
    parser.add_argument(
        "--idle-requests", type=int, default=300, help="calls of each with nothing running (default 300)"
    )
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.2f} at start (shared machine)"
    )
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        vehicle = default_quarter_car()
        write_recording_csv(folder / "recording.csv", simulate(vehicle, SimulationSettings(seed=0)).recording)
        write_vehicle(folder / "vehicle.toml", vehicle.known)
        write_large_csv(folder / "large.csv", args.upload_mb, folder / "recording.csv")
        size_mb = (folder / "large.csv").stat().st_size / 1e6
        keys = f'operator = ["{KEY}"]\n'
        upload_limit = ("--max-upload-mb", str(int(size_mb * 1.2) + 1))
        with realtime_service(folder, keys, "--log-level", "warning", *upload_limit) as (url, _pid):
            result = measure(url, folder, args.generations, format_vehicle(vehicle.known), args.idle_requests)
    report(result, size_mb)


def measure(url: str, folder: Path, generations: int, vehicle_toml: str, idle_calls: int) -> dict:
    auth = {"Authorization": f"Bearer {KEY}"}
    with httpx.Client(base_url=url, headers=auth, timeout=30) as client:

        def ready() -> bool:
            try:
                return bool(client.get("/api/v1/status").json()["worker"]["ready"])
            except httpx.TransportError:  # still starting
                return False

        wait_until(ready, 180, "worker ready", 0.5)
        idle = [(path, timed(client, path)) for _ in range(idle_calls) for path in PATHS]
        files = {
            "recording": (folder / "recording.csv").read_bytes(),
            "vehicle": (folder / "vehicle.toml").read_bytes(),
        }
        job = client.post(
            "/api/v1/jobs", files=files, data={"solver": "de", "generations": str(generations)}
        ).json()
        wait_until(
            lambda: client.get(f"/api/v1/jobs/{job['id']}").json()["status"] == "running", 60, "DE job", 0.05
        )
        sweep = client.post("/api/v1/sweeps", json={"duration_s": 20.0, "vehicle_toml": vehicle_toml})
        sweep.raise_for_status()
        # the upload from another process (curl), so that it does not share this process's interpreter
        began = time.perf_counter()
        uploader = subprocess.Popen(
            ["curl", "-sS", "-o", "/dev/null", "-w", "%{http_code}", "-H", f"Authorization: Bearer {KEY}",
             "-F", f"recording=@{folder / 'large.csv'}", "-F", f"vehicle=@{folder / 'vehicle.toml'}",
             "-F", "output_error=false", f"{url}/api/v1/jobs"],
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        samples: list[tuple[str, float, bool, bool, bool]] = []
        de = swept = False
        while uploader.poll() is None or not samples:
            for path in PATHS:
                elapsed, response = timed_response(client, path)
                if path.endswith("status"):
                    body = response.json()
                    de = (body["current_job"] or {}).get("id") == job["id"]
                    swept = bool((body.get("bench") or {}).get("busy"))
                samples.append((path, elapsed, uploader.poll() is None, de, swept))
        upload = {"status": uploader.communicate()[0].strip(), "seconds": time.perf_counter() - began}
        final = client.get(f"/api/v1/jobs/{job['id']}").json()
    return {"idle": idle, "samples": samples, "upload": upload, "job": final}


def timed_response(client: httpx.Client, path: str) -> tuple[float, httpx.Response]:
    began = time.perf_counter()
    response = client.get(path)
    elapsed = time.perf_counter() - began
    response.raise_for_status()
    return elapsed, response


def timed(client: httpx.Client, path: str) -> float:
    return timed_response(client, path)[0]


def report(result: dict, size_mb: float) -> None:
    samples = result["samples"]
    upload = result["upload"]
    print(
        f"\nupload of {size_mb:.1f} MB: HTTP {upload['status']} after {upload['seconds']:.1f} s; DE job "
        f"{result['job']['status']} ({result['job']['progress'] and result['job']['progress']['stage']})\n"
    )
    print("| request, while ... | calls | p50 (ms) | p99 (ms) | max (ms) |")
    print("|---|---:|---:|---:|---:|")
    verdicts = []
    for path in PATHS:
        print(row(f"GET {path}, idle (the machine's baseline)", [s for p, s in result["idle"] if p == path]))
        mine = [s for s in samples if s[0] == path]
        during = [s[1] for s in mine if s[2]]
        all_three = [s[1] for s in mine if s[2] and s[3] and s[4]]
        print(row(f"GET {path}, upload in flight", during))
        print(row(f"GET {path}, upload + DE job + sweep all at once", all_three))
        if during:
            p99, worst = percentile([x * 1e3 for x in during], 99), max(during) * 1e3
            verdicts.append(
                f"GET {path}: p99 {p99:.1f} ms (target < {TARGET_P99_MS:g})"
                + (f", max {worst:.1f} ms (target < {TARGET_MAX_MS:g})" if path.endswith("status") else "")
            )
    print("\n" + "; ".join(verdicts))
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
