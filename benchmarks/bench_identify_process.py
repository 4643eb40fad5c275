"""Benchmark (issue 15, item 1): `shockbench identify --json` as a whole process (gap included) against
scipy's differential_evolution with the seed's settings, also as a whole process, side by side in one run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_identify_process.py [--repeats 3]

The recording is a 12 s sweep at 1 kHz (11 s chirp 0-20 Hz ±4 mm plus 1 s settling) of a motorcycle corner
with the paper's bench figures (mass 109.3 kg, spring 14 040 N/m, tyre 101 018 N/m, τ 32.3 ms), a real
dyno-log damper, 5 µm white noise, simulated by the independent world (simulators/independent, DOP853 to
1e-9; it shares no code with the estimator). Both processes read the same recording CSV and vehicle TOML.

"scipy DE" is a Python process that reads them with the project's readers, builds the paper's objective
(estimator.equations.build, 20 curve points, nsample 5000, raw coordinates: the paper's unknowns) and runs
scipy.optimize.differential_evolution with the seed's settings: rand1bin, F 1, CR 0.3, NP 70 (a 70-member
initial population), 3000 generations, tol 0, no polishing; "immediate" is scipy's default updating (one
objective call per member), "deferred" is `vectorized=True, updating="deferred"` (one call per generation,
scipy's fastest mode). The rounds alternate the processes so that the machine's load falls on all alike;
the figures are medians. Wall time includes the interpreter's start and every import.
"""

from __future__ import annotations

import argparse
import compileall
import functools
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHOCKBENCH = Path(sys.executable).with_name("shockbench")
TARGET_RATIO = 30.0
GNU_TIME = "/usr/bin/time"


def write_motorcycle_recording(folder: Path) -> tuple[Path, Path]:
    """The benchmark's recording CSV and vehicle TOML, written by the independent world."""
    from simulators.independent.dampers import DYNO_LOGS, dyno_table
    from simulators.independent.excitation import Chirp
    from simulators.independent.files import write_recording
    from simulators.independent.sensors import SensorNoise
    from simulators.independent.vehicles import Corner, Vehicle
    from simulators.independent.world import WorldSettings, simulate

    corner = Corner(dyno_table(DYNO_LOGS[1]).scaled(1.8), 14.0, 14_040.0, 101_018.0, 1500.0, 0.0323)
    vehicle = Vehicle("motorcycle", 95.3, (corner,))
    settings = WorldSettings(chirp=Chirp(duration_s=11.0), settle_s=1.0, noise=SensorNoise(5e-6), seed=0)
    csv_path, toml_path = folder / "motorcycle.csv", folder / "motorcycle.toml"
    write_recording(simulate(vehicle, settings), csv_path, toml_path)
    return csv_path, toml_path


def run_scipy_de(csv_path: str, toml_path: str, updating: str, generations: int) -> None:
    """The child process of the "scipy DE" rows: read, build the objective, run scipy's DE, print θ."""
    import numpy as np
    from scipy.optimize import differential_evolution

    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.equations import build
    from estimator.identify import Coordinates, de_problem
    from estimator.vehicle import TyreModel

    recording, vehicle = read_recording_csv(csv_path), read_vehicle(toml_path)
    system = build(recording, vehicle, TyreModel.MAXWELL)
    problem = de_problem(system, vehicle, Coordinates.RAW)
    init = np.random.default_rng(0).uniform(problem.bounds[:, 0], problem.bounds[:, 1], (70, system.n_params))
    if updating == "deferred":
        extra = {"vectorized": True, "updating": "deferred"}
        objective = lambda z: problem.objective(np.asarray(z).T)  # noqa: E731 - scipy's (p, S) layout
    else:
        extra, objective = {}, problem.objective
    result = differential_evolution(
        objective,
        problem.bounds,
        strategy="rand1bin",
        mutation=1.0,
        recombination=0.3,
        maxiter=generations,
        init=init,
        tol=0,
        atol=0,
        polish=False,
        seed=0,
        **extra,
    )
    theta = problem.theta(result.x)
    print(f"objective {float(system.objective(theta)):.6g} sprung mass {theta[0]:.2f} kg")


@functools.cache
def compile_bytecode() -> None:
    """Write the project's bytecode (__pycache__) before the first process is measured, as any Python does
    at a package's first import: where PYTHONDONTWRITEBYTECODE is set (some sandboxes set it), every
    process would otherwise compile the modules it imports from source (about 0.07 s of a 0.9 s diagnose)."""
    for package in ("estimator", "service", "daq", "drivers", "simulators"):
        compileall.compile_dir(REPO / package, quiet=1)


def measured_process(command: list[str]) -> tuple[float, float, float, str]:
    """Run a child process (OPENBLAS_NUM_THREADS=1, from the repository root): its wall time (s), its own
    peak resident memory (MiB), its CPU time (user + system, s) and its stdout. A failure raises with its
    stderr.

    The peak RSS is GNU time's (%M, the child's ru_maxrss): the child is started from that small process,
    because a child forked from this one starts with this process's resident pages in its own figure."""
    compile_bytecode()
    environment = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    with tempfile.TemporaryDirectory(prefix="measured_process_") as folder:
        peak = Path(folder) / "peak_KiB"
        start = time.perf_counter()
        child = subprocess.run(
            [GNU_TIME, "-f", "%M %U %S", "-o", str(peak), *command],
            capture_output=True,
            env=environment,
            cwd=REPO,
        )
        seconds = time.perf_counter() - start
        if child.returncode != 0:
            reason = child.stderr.decode()[-500:]
            raise RuntimeError(f"{' '.join(command)} failed ({child.returncode}): {reason}")
        peak_KiB, user_s, system_s = (float(v) for v in peak.read_text().split()[-3:])
    return seconds, peak_KiB / 1024.0, user_s + system_s, child.stdout.decode()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="rounds (default 3; the figures are medians)")
    parser.add_argument("--generations", type=int, default=3000, help="DE generations (default 3000)")
    parser.add_argument(
        "--updating",
        default="immediate,deferred",
        help="scipy DE modes to run, comma-separated (default immediate,deferred)",
    )
    parser.add_argument("--scipy-de", nargs=2, metavar=("CSV", "TOML"), help=argparse.SUPPRESS)
    parser.add_argument("--mode", default="immediate", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.scipy_de:
        run_scipy_de(*args.scipy_de, args.mode, args.generations)
        return
    modes = [m for m in args.updating.split(",") if m]
    with tempfile.TemporaryDirectory(prefix="bench_identify_process_") as folder:
        csv_path, toml_path = write_motorcycle_recording(Path(folder))
        commands = {
            "identify": [str(SHOCKBENCH), "identify", str(csv_path), "--vehicle", str(toml_path), "--json"]
        }
        for mode in modes:
            commands[f"scipy DE ({mode})"] = [
                sys.executable, __file__, "--scipy-de", str(csv_path), str(toml_path),
                "--mode", mode, "--generations", str(args.generations),
            ]  # fmt: skip
        from estimator.simulation_kernel import kernel_in_use

        kernel = kernel_in_use()
        times: dict[str, list[float]] = {name: [] for name in commands}
        memory: dict[str, list[float]] = {name: [] for name in commands}
        cpu: dict[str, list[float]] = {name: [] for name in commands}
        load = [os.getloadavg()[0]]
        for round_index in range(args.repeats):
            for name, command in commands.items():
                seconds, peak_MiB, cpu_s, _ = measured_process(command)
                times[name].append(seconds)
                memory[name].append(peak_MiB)
                cpu[name].append(cpu_s)
                load.append(os.getloadavg()[0])
                print(
                    f"round {round_index + 1} {name}: {seconds:.2f} s, CPU {cpu_s:.2f} s, {peak_MiB:.0f} MiB",
                    file=sys.stderr,
                )
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
        f"load average {min(load):.1f}-{max(load):.1f} during the run; output-error kernel: {kernel}\n"
    )
    print(f"12 s at 1 kHz (independent world, motorcycle corner); {args.repeats} rounds, medians\n")
    print(
        "| process | wall time (s), median | each round (s) | scipy DE / identify, wall | CPU time (s), "
        "median | scipy DE / identify, CPU | peak RSS (MiB) |"
    )
    print("|---|---:|---|---:|---:|---:|---:|")
    identify_s, identify_cpu_s = statistics.median(times["identify"]), statistics.median(cpu["identify"])
    for name, values in times.items():
        ratio = statistics.median(values) / identify_s
        cpu_ratio = statistics.median(cpu[name]) / identify_cpu_s
        print(
            f"| {name} | {statistics.median(values):.2f} | {', '.join(f'{v:.2f}' for v in values)} | "
            f"{'-' if name == 'identify' else f'{ratio:.1f}x'} | {statistics.median(cpu[name]):.2f} | "
            f"{'-' if name == 'identify' else f'{cpu_ratio:.1f}x'} | {max(memory[name]):.0f} |"
        )
    for name in commands:
        if name != "identify":
            ratio = statistics.median(times[name]) / identify_s
            verdict = "met" if ratio >= TARGET_RATIO else "NOT met"
            print(f"\n{name} / identify = {ratio:.1f}x; target >= {TARGET_RATIO:g}x: {verdict}")


if __name__ == "__main__":
    main()
