"""Benchmark (issue 15, item 5): peak resident memory of `shockbench identify --json` and `shockbench
diagnose --json` on a 60 s, 1 kHz axle recording, each as a whole process.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_memory.py [--seconds 60] [--repeats 1]

The recording is the project's simulator's default axle (two valve-model dampers, the right one 15% weaker,
anti-roll bar, Maxwell tyres, 5 µm noise): a 59 s sweep 0-20 Hz ±4 mm plus 1 s settling at 1 kHz, 60 001
samples of 7 columns, written as a recording CSV with its vehicle file. Each command runs in its own child
process started by GNU time (/usr/bin/time, its %M: the child's ru_maxrss, the largest of it and the
processes it waited for), so this process's memory is not counted. The doctor's fits run in processes it
forks (estimator.forked_map), so a second run samples the whole process tree every 10 ms and reports the
peak of its summed proportional set size (PSS: a page shared copy-on-write counts once, split between the
processes that share it) from /proc/PID/smaps_rollup (Linux). Target: under 1 GiB for both, the tree's.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_identify_process import REPO, SHOCKBENCH, measured_process

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


def _descendants(root: int) -> list[int]:
    """root and every process below it, from the parent ids in /proc/*/stat."""
    parents: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as stat:
                    parents[int(entry)] = int(stat.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue  # ended meanwhile
    tree, frontier = [root], [root]
    while frontier:
        frontier = [pid for pid, parent in parents.items() if parent in frontier]
        tree += frontier
    return tree


def _pss_KiB(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/smaps_rollup") as rollup:
            return next((int(line.split()[1]) for line in rollup if line.startswith("Pss:")), 0)
    except OSError:
        return 0  # ended meanwhile


def tree_peak(command: list[str]) -> tuple[float, float, int]:
    """Run `command` (OPENBLAS_NUM_THREADS=1): wall time (s), the peak of its process tree's summed PSS
    (MiB, sampled every 10 ms) and the most processes seen at once."""
    environment = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    start = time.perf_counter()
    child = subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=environment, cwd=REPO
    )
    peak_KiB, most = 0, 0
    while child.poll() is None:
        tree = _descendants(child.pid)
        peak_KiB, most = max(peak_KiB, sum(_pss_KiB(pid) for pid in tree)), max(most, len(tree))
        time.sleep(0.01)
    seconds = time.perf_counter() - start
    if child.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed ({child.returncode}): {child.stderr.read()[-500:]!r}")
    return seconds, peak_KiB / 1024.0, most


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
                argv = [str(SHOCKBENCH), command, str(csv_path), "--vehicle", str(toml_path), "--json"]
                seconds, peak_MiB, _, _ = measured_process(argv)
                _, tree_MiB, processes = tree_peak(argv)
                rows.append((command, seconds, peak_MiB, tree_MiB, processes))
                print(
                    f"{command}: {seconds:.1f} s, {peak_MiB:.0f} MiB, tree {tree_MiB:.0f} MiB",
                    file=sys.stderr,
                )
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.1f} at the end\n"
    )
    print(f"{args.seconds:g} s at 1 kHz, default axle, recording CSV {size_MB:.1f} MB\n")
    print(
        "| process | wall time (s) | peak RSS, largest process (MiB) | peak PSS, process tree (MiB) "
        "| target < 1024 MiB |"
    )
    print("|---|---:|---:|---:|---|")
    for command, seconds, peak_MiB, tree_MiB, processes in rows:
        verdict = "met" if tree_MiB < TARGET_MIB else "NOT met"
        tree = f"{tree_MiB:.0f} ({processes} processes at most)"
        print(f"| shockbench {command} --json | {seconds:.1f} | {peak_MiB:.0f} | {tree} | {verdict} |")


if __name__ == "__main__":
    main()
