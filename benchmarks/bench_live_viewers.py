"""Benchmark: does watching a sweep live slow the acquisition? The same real-time sweep with 0 and with
`--viewers` screens reading GET /api/v1/bench/live (issue 17, item 5).

    .venv/bin/python benchmarks/bench_live_viewers.py
    .venv/bin/python benchmarks/bench_live_viewers.py --viewers 3 --duration-s 20 --rounds 2

Processes besides this one: `shockbench sim-devices` (simulated lasers and exciter on real transports, on
the wall clock, so the acquisition runs in real time as on a bench) and `python -m service.cli.serve
--config` on it. Each round runs one sweep with no viewer and one with `--viewers` threads of this process,
each holding its own live stream (httpx) the way a browser does (fetch + ReadableStream). Per sweep it
reports: the recording's rows and gap samples (from its HDF5 file: a lost sample is a gap there), whether
the recording is complete, the service process's CPU seconds during the sweep, and per viewer the live
rows of this sweep it received (the recording's rows / 10 if none was lost on the way), the rows it
missed (a stream that fell behind) and its event rate.
The machine is shared with other work: state the load average with the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx

from daq.formats.vehicle_file import format_vehicle
from simulators.vehicle_sim import default_quarter_car

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "service"))

from live_server import wait_until  # the tests' deadline-bounded wait, shared
from realtime_bench import realtime_service, recording_rows, sweep_status

KEY = "benchmark-operator-key-0123456789"
AUTH = {"Authorization": f"Bearer {KEY}"}


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Viewer(threading.Thread):
    """One screen: reads the live stream until told to stop, counting rows, misses and events."""

    def __init__(self, url: str) -> None:
        super().__init__(daemon=True)
        self.url = url
        self.rows: dict[int | None, int] = {}
        self.missed = self.events = 0
        self.stop = threading.Event()
        self.connected = threading.Event()

    def run(self) -> None:
        with httpx.stream("GET", f"{self.url}/api/v1/bench/live", headers=AUTH, timeout=None) as stream:
            self.connected.set()
            name = ""
            for line in stream.iter_lines():
                if self.stop.is_set():
                    return
                if line.startswith("event: "):
                    name = line[7:]
                elif line.startswith("data: ") and name == "samples":
                    data = json.loads(line[6:])
                    sweep = data["sweep_id"]
                    self.rows[sweep] = self.rows.get(sweep, 0) + len(data["t_s"])
                    self.missed += data["missed"]
                    self.events += 1


def one_sweep(url: str, pid: int, vehicle_toml: str, duration_s: float, viewers: int) -> dict[str, Any]:
    screens = [Viewer(url) for _ in range(viewers)]
    for screen in screens:
        screen.start()
        screen.connected.wait(30)
    with httpx.Client(base_url=url, headers=AUTH, timeout=60) as client:
        cpu0, wall0 = cpu_s(pid), time.perf_counter()
        answer = client.post(
            "/api/v1/sweeps", json={"duration_s": duration_s, "settle_s": 1.0, "vehicle_toml": vehicle_toml}
        )
        answer.raise_for_status()
        sweep_id = answer.json()["id"]

        def ended() -> dict[str, Any] | None:
            sweep: dict[str, Any] = client.get(f"/api/v1/sweeps/{sweep_id}").json()
            return sweep if sweep["status"] in ("complete", "failed", "aborted") else None

        sweep = wait_until(ended, duration_s + 120, f"sweep {sweep_id}", 0.2)
        cpu, wall = cpu_s(pid) - cpu0, time.perf_counter() - wall0
        recording = client.get(f"/api/v1/sweeps/{sweep_id}/recording.h5")
    for screen in screens:
        screen.stop.set()
    rows, gap_samples = recording_rows(recording.content)
    return {
        "viewers": viewers,
        "status": sweep_status(sweep),
        "complete": sweep["complete"],
        "rows": rows,
        "gap_samples": gap_samples,
        "service_cpu_s": cpu,
        "wall_s": wall,
        "screens": [(s.rows.get(sweep_id, 0), s.missed, s.events / wall) for s in screens],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--viewers", type=int, default=3, help="live streams during the watched sweep")
    parser.add_argument("--duration-s", type=float, default=20.0, help="sweep duration (default 20 s)")
    parser.add_argument("--rounds", type=int, default=2, help="pairs of sweeps, alternating (default 2)")
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.2f} at start (shared machine)"
    )
    results: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        keys = f'operator = ["{KEY}"]\n'
        with realtime_service(folder, keys, "--log-level", "warning") as (url, pid):
            vehicle_toml = format_vehicle(default_quarter_car().known)
            for _ in range(args.rounds):
                for viewers in (0, args.viewers):
                    results.append(one_sweep(url, pid, vehicle_toml, args.duration_s, viewers))
    print(f"load average {os.getloadavg()[0]:.2f} at end")
    print(
        "| viewers | status | rows | gap samples | service CPU (s) | wall (s) "
        "| per viewer: rows of this sweep, missed, events/s |"
    )
    print("|---:|---|---:|---:|---:|---:|---|")
    for r in results:
        screens = "; ".join(f"{rows}, {missed}, {rate:.1f}" for rows, missed, rate in r["screens"]) or "-"
        print(
            f"| {r['viewers']} | {r['status']} | {r['rows']} | {r['gap_samples']} | {r['service_cpu_s']:.2f} "
            f"| {r['wall_s']:.1f} | {screens} |"
        )


if __name__ == "__main__":
    main()
