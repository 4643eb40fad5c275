"""Benchmark: the operator page's live chart in real browsers during a real-time sweep: how often each
page redraws it, and whether the acquisition lost a sample with that many browsers watching (issue 17,
item 5: refreshed at 10 Hz or more, no lost samples with three browsers).

    .venv/bin/python benchmarks/bench_web_chart.py
    .venv/bin/python benchmarks/bench_web_chart.py --browsers 3 --duration-s 20 --rounds 2

Processes besides this one: `shockbench sim-devices` (simulated lasers and exciter on real transports, on
the wall clock, so the sweep runs in real time as on a bench), `python -m service.cli.serve --config` on
it, and `--browsers` headless Chromiums (Debian's chromium and chromium-driver, driven by selenium) each
showing the page signed in with a viewer key. Per sweep: the recording's rows and gap samples (from its
HDF5 file: a lost sample is a gap there), and per browser the chart's frames drawn per second of
recording (the page counts its frames in the canvas's data-frames) and the rows it holds at the end.
The machine is shared with other work: state the load average with the figures.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import httpx

from daq.formats.vehicle_file import format_vehicle
from simulators.vehicle_sim import default_quarter_car

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "service"))

from headless_chromium import chromium_driver, find_chromium  # the browser tests' Chromium
from live_server import wait_until  # the tests' deadline-bounded wait, shared
from realtime_bench import realtime_service, recording_rows, sweep_status

OPERATOR = "benchmark-operator-key-0123456789"
VIEWER = "benchmark-viewer-key-0123456789"


def frames(driver: Any) -> int:
    value = driver.execute_script("return document.getElementById('live-chart').dataset.frames || '0'")
    return int(value)


def open_page(driver: Any, url: str) -> None:
    """Sign in with the viewer key and wait until the page follows the bench."""
    driver.get(url + "/")
    driver.execute_script(
        "const key = document.getElementById('login-key'); key.value = arguments[0];"
        "document.getElementById('login-form').requestSubmit();",
        VIEWER,
    )
    wait_until(
        lambda: driver.execute_script(
            "return document.getElementById('bench-status').textContent"
        ).startswith("Bench"),
        60,
        "page signed in",
        0.1,
    )


def one_sweep(url: str, drivers: list[Any], vehicle_toml: str, duration_s: float) -> dict[str, Any]:
    auth = {"Authorization": f"Bearer {OPERATOR}"}
    with httpx.Client(base_url=url, headers=auth, timeout=60) as client:
        answer = client.post(
            "/api/v1/sweeps", json={"duration_s": duration_s, "settle_s": 1.0, "vehicle_toml": vehicle_toml}
        )
        answer.raise_for_status()
        sweep_id = answer.json()["id"]

        def recording() -> bool:
            sweep = client.get(f"/api/v1/sweeps/{sweep_id}").json()
            return sweep["status"] != "requested" and (sweep["progress"] or {}).get("rows", 0) > 0

        wait_until(recording, 120, "recording", 0.05)
        before, wall0 = [frames(d) for d in drivers], time.perf_counter()

        def ended() -> dict[str, Any] | None:
            sweep: dict[str, Any] = client.get(f"/api/v1/sweeps/{sweep_id}").json()
            return sweep if sweep["status"] in ("complete", "failed", "aborted") else None

        sweep = wait_until(ended, duration_s + 120, f"sweep {sweep_id}", 0.05)
        wall = time.perf_counter() - wall0
        after = [frames(d) for d in drivers]
        points = [
            int(d.execute_script("return document.getElementById('live-chart').dataset.points"))
            for d in drivers
        ]
        h5 = client.get(f"/api/v1/sweeps/{sweep_id}/recording.h5")
    rows, gap_samples = recording_rows(h5.content)
    return {
        "browsers": len(drivers),
        "status": sweep_status(sweep),
        "rows": rows,
        "gap_samples": gap_samples,
        "wall_s": wall,
        "fps": [(a - b) / wall for a, b in zip(after, before, strict=True)],
        "points": points,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--browsers", type=int, default=3, help="headless Chromiums watching (default 3)")
    parser.add_argument("--duration-s", type=float, default=20.0, help="sweep duration (default 20 s)")
    parser.add_argument("--rounds", type=int, default=2, help="sweeps (default 2)")
    args = parser.parse_args()
    chromium = find_chromium()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.2f} at start (shared machine)"
    )
    results: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp, ExitStack() as browsers:
        folder = Path(tmp)
        keys = f'operator = ["{OPERATOR}"]\nviewer = ["{VIEWER}"]\n'
        with realtime_service(folder, keys, "--log-level", "warning") as (url, _pid):
            drivers = [
                browsers.enter_context(chromium_driver(chromium, folder / f"downloads-{i}"))
                for i in range(args.browsers)
            ]
            for driver in drivers:
                open_page(driver, url)
            vehicle_toml = format_vehicle(default_quarter_car().known)
            for _ in range(args.rounds):
                results.append(one_sweep(url, drivers, vehicle_toml, args.duration_s))
            browsers.close()
    print(f"load average {os.getloadavg()[0]:.2f} at end")
    print("| browsers | status | rows | gap samples | wall (s) | per browser: chart frames/s, points held |")
    print("|---:|---|---:|---:|---:|---|")
    for r in results:
        screens = "; ".join(f"{fps:.1f}, {points}" for fps, points in zip(r["fps"], r["points"], strict=True))
        figures = f"{r['rows']} | {r['gap_samples']} | {r['wall_s']:.1f}"
        print(f"| {r['browsers']} | {r['status']} | {figures} | {screens} |")


if __name__ == "__main__":
    main()
