"""Benchmark (issue 15, item 3): an identification job through the service against `shockbench identify
--json` for the same files, and GET /api/v1/status latency while such jobs run, side by side in one run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_service_job.py [--repeats 5]

Files: the 12 s, 1 kHz motorcycle recording of bench_identify_process.py (independent world) and its vehicle
file. The service runs as in bench_status_latency.py (`python -m service.cli.serve`, port 0, a keys file, a
fresh data directory, worker nice +5); its worker has imported the estimator and loaded the output-error
kernel before it says it is ready. Each round, in turn:

1. the CLI: `shockbench identify REC.csv --vehicle V.toml --json` as a whole process (wall time);
2. the job alone: POST /api/v1/jobs (multipart, default options: exact solver, output-error gap, then the
   PNG and SVG plots the job stores as artefacts), then GET /api/v1/jobs/{id} every 10 ms until it has
   succeeded; "result ready" is from before the POST to the first answer that says succeeded;
3. the job again, with GET /api/v1/status called back to back on one keep-alive client until the worker is
   idle: those calls' latencies are the "while a job runs" samples (the back-to-back calls take CPU from
   the job, so its time is not counted in 2).

Targets: result ready within 1.5x the CLI's time (medians); status p99 < 50 ms while the jobs run.
"""

from __future__ import annotations

import argparse
import os
import platform
import signal
import statistics
import tempfile
import time
from pathlib import Path

import httpx
from bench_identify_process import SHOCKBENCH, measured_process, write_motorcycle_recording
from bench_status_latency import KEY, percentile, row, start_service, timed_status
from live_server import (
    wait_until,  # the tests' deadline-bounded wait (bench_status_latency puts it on the path)
)

TARGET_RATIO = 1.5
TARGET_P99_MS = 50.0
POLL_S = 0.01


def job_until_done(client: httpx.Client, files: dict[str, bytes], status_calls: list[float] | None) -> float:
    """Submit an identification job and wait for its result: seconds from before the POST until an answer
    says succeeded. With status_calls, GET /status is called back to back meanwhile and timed into it."""
    start = time.perf_counter()
    response = client.post("/api/v1/jobs", files=files)
    response.raise_for_status()
    job_id = response.json()["id"]
    while True:
        if status_calls is None:
            time.sleep(POLL_S)
        else:
            elapsed, _ = timed_status(client)
            status_calls.append(elapsed)
        status = client.get(f"/api/v1/jobs/{job_id}").json()["status"]
        if status == "succeeded":
            return time.perf_counter() - start
        if status in ("failed", "cancelled"):
            raise RuntimeError(f"job {job_id} {status}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="rounds (default 5; the figures are medians)")
    parser.add_argument("--worker-nice", type=int, default=5, help="the service's --worker-nice (default 5)")
    args = parser.parse_args()
    cli_s: list[float] = []
    job_s: list[float] = []
    status_calls: list[float] = []
    idle: list[float] = []
    load = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory(prefix="bench_service_job_") as tmp:
        folder = Path(tmp)
        csv_path, toml_path = write_motorcycle_recording(folder)
        files = {"recording": csv_path.read_bytes(), "vehicle": toml_path.read_bytes()}
        process, url = start_service(folder, args.worker_nice)
        try:
            with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {KEY}"}, timeout=30) as client:
                wait_until(
                    lambda: client.get("/api/v1/status").json()["worker"]["ready"], 120, "worker ready", 0.2
                )
                idle = [timed_status(client)[0] for _ in range(200)]
                job_until_done(client, files, None)  # the service's first job: warm its caches and database
                for round_index in range(args.repeats):
                    cli_s.append(
                        measured_process(
                            [
                                str(SHOCKBENCH),
                                "identify",
                                str(csv_path),
                                "--vehicle",
                                str(toml_path),
                                "--json",
                            ]
                        )[0]
                    )
                    job_s.append(job_until_done(client, files, None))
                    job_until_done(client, files, status_calls)
                    load.append(os.getloadavg()[0])
                    print(
                        f"round {round_index + 1}: CLI {cli_s[-1]:.2f} s, job {job_s[-1]:.2f} s", flush=True
                    )
        finally:
            process.send_signal(signal.SIGINT)
            process.wait(60)
    ratio = statistics.median(job_s) / statistics.median(cli_s)
    p99 = percentile([s * 1e3 for s in status_calls], 99)
    print(
        f"\nmachine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
        f"load average {min(load):.1f}-{max(load):.1f} during the run; {args.repeats} rounds\n"
    )
    print("| identification of the 12 s, 1 kHz recording | median (s) | each round (s) |")
    print("|---|---:|---|")
    print(f"| `shockbench identify --json` (whole process) | {statistics.median(cli_s):.2f} | "
          f"{', '.join(f'{v:.2f}' for v in cli_s)} |")  # fmt: skip
    print(f"| service job: POST to result ready (with PNG + SVG plots) | {statistics.median(job_s):.2f} | "
          f"{', '.join(f'{v:.2f}' for v in job_s)} |")  # fmt: skip
    print(
        f"\njob / CLI = {ratio:.2f}x; target <= {TARGET_RATIO:g}x: "
        f"{'met' if ratio <= TARGET_RATIO else 'NOT met'}\n"
    )
    print("| GET /api/v1/status | calls | p50 (ms) | p99 (ms) | max (ms) | mean (ms) |")
    print("|---|---:|---:|---:|---:|---:|")
    print(row("idle", idle))
    print(row("while identification jobs run", status_calls))
    print(f"\nstatus p99 while jobs run {p99:.1f} ms; target < {TARGET_P99_MS:g} ms: "
          f"{'met' if p99 < TARGET_P99_MS else 'NOT met'}")  # fmt: skip


if __name__ == "__main__":
    main()
