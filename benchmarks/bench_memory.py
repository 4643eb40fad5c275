"""Benchmark (issue 15, item 5): peak resident memory of `shockbench identify --json` and `shockbench
diagnose --json` on a 60 s, 1 kHz axle recording, each as a whole process.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_memory.py [--seconds 60] [--repeats 1]

The recording is the project's simulator's default axle (two valve-model dampers, the right one 15% weaker,
anti-roll bar, Maxwell tyres, 5 µm noise): a 59 s sweep 0-20 Hz ±4 mm plus 1 s settling at 1 kHz, 60 001
samples of 7 columns, written as a recording CSV with its vehicle file. Each command runs in its own child
process started by GNU time (/usr/bin/time, its %M: the child's ru_maxrss), so this process's memory is
not counted. Target: under 1 GiB for both.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
from pathlib import Path

from bench_identify_process import SHOCKBENCH, measured_process

TARGET_MIB = 1024.0


def write_axle_recording(folder: Path, seconds: float) -> tuple[Path, Path]:
    from daq.formats.recording_csv import write_recording_csv
    from daq.formats.vehicle_file import write_vehicle
    from estimator.sweep import SweepSettings
    from simulators.vehicle_sim import SimulationSettings, default_axle, simulate

    vehicle = default_axle()
    settings = SimulationSettings(sweep=SweepSettings(duration_s=seconds - 1.0), settle_s=1.0, seed=0)
    csv_path, toml_path = folder / "axle.csv", folder / "axle.toml"
    write_recording_csv(csv_path, simulate(vehicle, settings).recording)
    write_vehicle(toml_path, vehicle.known)
    return csv_path, toml_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="recording length, s (default 60)")
    parser.add_argument("--repeats", type=int, default=1, help="runs of each command (default 1)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_memory_") as folder:
        csv_path, toml_path = write_axle_recording(Path(folder), args.seconds)
        size_MB = csv_path.stat().st_size / 1e6
        rows = []
        for command in ("identify", "diagnose"):
            for _ in range(args.repeats):
                seconds, peak_MiB, _, _ = measured_process(
                    [str(SHOCKBENCH), command, str(csv_path), "--vehicle", str(toml_path), "--json"]
                )
                rows.append((command, seconds, peak_MiB))
                print(f"{command}: {seconds:.1f} s, {peak_MiB:.0f} MiB", file=sys.stderr)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.1f} at the end\n"
    )
    print(f"{args.seconds:g} s at 1 kHz, default axle, recording CSV {size_MB:.1f} MB\n")
    print("| process | wall time (s) | peak RSS (MiB) | target < 1024 MiB |")
    print("|---|---:|---:|---|")
    for command, seconds, peak_MiB in rows:
        verdict = "met" if peak_MiB < TARGET_MIB else "NOT met"
        print(f"| shockbench {command} --json | {seconds:.1f} | {peak_MiB:.0f} | {verdict} |")


if __name__ == "__main__":
    main()
