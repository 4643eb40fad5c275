"""Benchmark: `shockbench reanalyse` on 100 recordings, 2 Dask worker processes against serial (issue 18,
item 6).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_reanalyse.py
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_reanalyse.py --recordings 100 --distinct 20 \
        --seconds 6 --workdir /tmp/reanalyse-bench

The archive: `--distinct` quarter-car sweeps of `--seconds` s at 1 kHz simulated by
simulators.vehicle_sim (default car, valve damper, 5 µm noise, seeds 0..distinct-1), each copied until
there are `--recordings` files (every file is identified on its own; copies only save simulation time),
with one vehicle.toml. Kept in --workdir between runs.

Each mode is one whole process, timed from start to exit (imports, cluster start and shutdown included),
each into a fresh output folder:
- loop: a plain Python loop over service.reanalyse.task.run_task in one process (serial, no Dask);
- workers1: `shockbench reanalyse ARCHIVE --out OUT --workers 1` (a LocalCluster of one process);
- workers2: `shockbench reanalyse ARCHIVE --out OUT --workers 2`.
The load average (1 min) is read before and after each; the machine is shared, so say the load.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "service.cli.main", "reanalyse"]
LOOP = """
import sys
from pathlib import Path
from service.reanalyse.sources import items_in_folder
from service.reanalyse.task import Analysis, AnalysisOptions, Task, run_task
failed = [o.reason for o in (run_task(Task(item, Analysis.IDENTIFY, AnalysisOptions()))
                             for item in items_in_folder(Path(sys.argv[1])))
          if not o.ok]
assert not failed, failed
"""


def make_archive(
    folder: Path, recordings: int, distinct: int, seconds: float, unique_copies: bool = False
) -> None:
    """The archive described in the module docstring (made once; reused when it is complete).
    unique_copies: each copy starts with a comment line of its own, so that no two files share their bytes
    (an archive in a database keeps one recording per content hash)."""
    from daq.formats.recording_csv import write_recording_csv
    from daq.formats.vehicle_file import write_vehicle
    from estimator.sweep import SweepSettings
    from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate

    names = [folder / f"rec-{index:03d}.csv" for index in range(recordings)]
    if all(path.is_file() for path in names) and (folder / "vehicle.toml").is_file():
        return
    folder.mkdir(parents=True, exist_ok=True)
    vehicle = default_quarter_car()
    write_vehicle(folder / "vehicle.toml", vehicle.known)
    start = time.perf_counter()
    for seed in range(distinct):
        settings = SimulationSettings(sweep=SweepSettings(duration_s=seconds), seed=seed)
        write_recording_csv(names[seed], simulate(vehicle, settings).recording)
    for index in range(distinct, recordings):
        if unique_copies:
            names[index].write_text(f"# copy: {index}\n{names[index % distinct].read_text()}")
        else:
            shutil.copy(names[index % distinct], names[index])
    print(f"simulated {distinct} sweeps of {seconds:g} s in {time.perf_counter() - start:.0f} s", flush=True)


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(command: list[str]) -> tuple[float, float, float, float]:
    """(wall s, CPU s of the process and the processes it started and reaped (Dask's workers), load
    average before, after) of a process that must succeed."""
    before, cpu = os.getloadavg()[0], _children_cpu_s()
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({done.returncode}): {done.stderr[-2000:]}")
    return wall, _children_cpu_s() - cpu, before, os.getloadavg()[0]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--recordings", type=int, default=100)
    parser.add_argument("--distinct", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument(
        "--workdir", type=Path, default=Path(tempfile.gettempdir()) / "shockbench-reanalyse-bench"
    )
    parser.add_argument(
        "--modes", default="loop,workers1,workers2", help="comma list of loop, workers1, workers2"
    )
    parser.add_argument("--repeats", type=int, default=1, help="rounds of every mode, interleaved (median)")
    args = parser.parse_args()

    archive = args.workdir / "archive"
    make_archive(archive, args.recordings, args.distinct, args.seconds)
    commands = {
        "loop": [sys.executable, "-c", LOOP, str(archive)],
        "workers1": [*CLI, str(archive), "--out", "{out}", "--workers", "1"],
        "workers2": [*CLI, str(archive), "--out", "{out}", "--workers", "2"],
    }
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}; "
        f"{args.recordings} recordings of {args.seconds:g} s ({args.distinct} distinct)",
        flush=True,
    )
    print(f"| mode | wall (median of {args.repeats}) | per recording | CPU, all processes | load average |")
    modes = args.modes.split(",")
    runs: dict[str, list[tuple[float, float, float, float]]] = {mode: [] for mode in modes}
    for _ in range(args.repeats):
        for mode in modes:
            out = args.workdir / f"out-{mode}"
            shutil.rmtree(out, ignore_errors=True)
            runs[mode].append(timed([part.replace("{out}", str(out)) for part in commands[mode]]))
            wall, cpu, before, after = runs[mode][-1]
            print(
                f"  {mode}: {wall:.1f} s wall, {cpu:.1f} s CPU, load {before:.1f} -> {after:.1f}", flush=True
            )
    walls = {}
    for mode in modes:
        wall = walls[mode] = statistics.median(run[0] for run in runs[mode])
        cpu = statistics.median(run[1] for run in runs[mode])
        loads = [load for run in runs[mode] for load in run[2:]]
        print(
            f"| {mode} | {wall:.1f} s | {wall / args.recordings:.2f} s | {cpu:.1f} s | "
            f"{min(loads):.1f}-{max(loads):.1f} |",
            flush=True,
        )
    serial = walls.get("loop") or walls.get("workers1")
    if serial and "workers2" in walls:
        print(
            f"speed-up of 2 workers against serial ({'loop' if 'loop' in walls else 'workers1'}): "
            f"{serial / walls['workers2']:.2f}x"
        )


if __name__ == "__main__":
    main()
