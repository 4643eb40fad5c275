"""Benchmark: acquisition soak at 1 kHz x 6 channels over real transports.

    .venv/bin/python benchmarks/bench_soak.py                 # 600 s (the issue's 10 minutes)
    .venv/bin/python benchmarks/bench_soak.py --seconds 60    # a shorter run

`shockbench sim-devices --vehicle-preset axle --step-s 0.002` serves a simulated axle bench in a separate
process on the wall clock (a 2 ms integration step: at 1 ms the axle's Python integration alone takes 0.74
of a core, and with six amplifier servers and the Modbus drive on one interpreter the simulator falls behind
real time and starves its own drive of keep-alives; what the soak measures is the acquisition): six
streaming ZX-L amplifiers (1 kHz on their own clocks) on loopback TCP sockets and a Modbus TCP plate drive.
This process then runs one sweep through the normal path (`daq.sweep.run.run_sweep` with real-time pacing:
one polling thread per amplifier line, the recorder, the HDF5 writer) for the whole soak: a linear 0-20 Hz
sweep of `--seconds` at 4 mm.

Reported: rows and gap rows in the recording, ring-buffer overruns, samples lost by the amplifiers' buffers,
failed reads, each channel's achieved rate, and the CPU of this process (acquisition and recording
together) as a fraction of one core, overall and minute by minute, next to the simulator process's.
Targets of the issue: gaps = 0, overruns = 0, acquisition below half a core.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import os
import platform
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from daq.bench_config import load_bench_config
from daq.storage.hdf5_recording import load_recording
from daq.sweep.model import SweepRequest
from daq.sweep.pacing import RealtimePacing
from daq.sweep.plan import plan_sweep
from daq.sweep.run import run_sweep
from drivers.exciter.envelope import EnvelopeLimits
from estimator.sweep import SweepSettings

START_TIMEOUT_S = 30.0
MINUTE_S = 60.0


class CpuPerMinute:
    """This process's CPU as a fraction of one core, minute by minute (a background thread): a cost that
    grows with the recording's length shows up as a rising series, which one average would hide."""

    def __init__(self) -> None:
        self.fractions: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cpu per minute", daemon=True)

    def __enter__(self) -> CpuPerMinute:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        wall0, cpu0 = time.monotonic(), time.process_time()
        while not self._stop.wait(MINUTE_S):
            wall, cpu = time.monotonic(), time.process_time()
            self.fractions.append((cpu - cpu0) / (wall - wall0))
            wall0, cpu0 = wall, cpu


def process_cpu_s(pid: int) -> float:
    """User + system CPU seconds of another process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_simulator(config: Path) -> subprocess.Popen[bytes]:
    shockbench = Path(sys.executable).with_name("shockbench")
    process = subprocess.Popen(
        [
            str(shockbench),
            "sim-devices",
            "--config",
            str(config),
            "--vehicle-preset",
            "axle",
            "--step-s",
            "0.002",
        ],
        stdout=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + START_TIMEOUT_S
    while not config.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            raise SystemExit("sim-devices did not start")
        time.sleep(0.1)
    return process


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0, help="soak duration (default 600)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        config_path = Path(folder) / "bench.toml"
        simulator = start_simulator(config_path)
        try:
            # a soak bench: sweeps longer than the default envelope's 300 s (up to the hard limit, 1 h)
            limits = EnvelopeLimits(max_duration_s=max(args.seconds, EnvelopeLimits.max_duration_s))
            config = dataclasses.replace(load_bench_config(config_path), envelope=limits)
            request = SweepRequest(SweepSettings(duration_s=args.seconds), settle_s=0.0)
            sim_cpu0 = process_cpu_s(simulator.pid)
            out = Path(folder) / "soak.h5"
            with CpuPerMinute() as per_minute:
                plan = plan_sweep(config, request)
                outcome = asyncio.run(run_sweep(config, plan, out, pacing=RealtimePacing()))
            sim_cpu = process_cpu_s(simulator.pid) - sim_cpu0
            stored = load_recording(out)
        finally:
            simulator.send_signal(signal.SIGINT)
            simulator.wait(timeout=30)
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}"
    )
    print(f"soak: {args.seconds:g} s sweep, {len(config.lasers)} channels, recording {outcome.summary()}")
    print(
        f"rows {outcome.rows}, gap rows {outcome.gap_rows} (file: {stored.metadata['gaps']} gaps), "
        f"ring-buffer overruns {outcome.overrun_samples}"
    )
    for source in outcome.sources:
        print(
            f"  {source.channel:6} {source.achieved_rate_Hz:8.2f} Hz  samples {source.samples}  lost "
            f"{source.lost_samples}  failed reads {source.failed_reads}  reads {source.reads}"
        )
    print(
        f"acquisition process CPU: {outcome.cpu_s:.1f} s over {outcome.wall_s:.1f} s wall = "
        f"{outcome.cpu_s / outcome.wall_s:.3f} of a core (target < 0.5)"
    )
    minutes = ", ".join(f"{f:.2f}" for f in per_minute.fractions)
    print(f"acquisition process CPU minute by minute: {minutes or 'under a minute'}")
    print(f"simulator process CPU: {sim_cpu:.1f} s = {sim_cpu / outcome.wall_s:.3f} of a core")
    ok = (
        outcome.complete
        and outcome.gap_rows == 0
        and outcome.overrun_samples == 0
        and all(s.lost_samples == 0 for s in outcome.sources)
        and outcome.cpu_s / outcome.wall_s < 0.5
    )
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
