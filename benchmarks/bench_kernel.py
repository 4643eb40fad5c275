"""Benchmark: the compiled output-error simulation (estimator/simulation_kernel.py) against the Python
reference integrator (estimator.dynamics.integrate_rk4), and `shockbench --help`, side by side in one run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_kernel.py
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_kernel.py --baseline-commit 67fc87b

1. 12 s at 1 kHz (12 000 Runge-Kutta steps) of a quarter car with a 20-point piecewise-linear damper and a
   Maxwell tyre: one model (as identify's output-error gap), and a population of 20 models with their own
   plates, curves and effects (Coulomb friction, cubic spring, lift-off, tyre dashpot), as the doctor
   simulates its candidates. The reference runs once (seconds), the kernel is the median of 7 runs; the
   largest relative difference of the trajectories is printed too.
2. The kernel's fixed cost in a fresh process that has imported scipy (as identify and diagnose have):
   importing numba and loading the compiled kernel from the on-disk cache (the compile itself is paid once
   per machine and source version; warmed first here).
3. `shockbench --help`, whole process, median of 5: this tree, and the tree at --baseline-commit (before
   the lazy imports), extracted with `git archive` into a temporary folder and run from there.

Prints lines ready for BENCHMARKS.md. The machine is shared, so compare the ratios, not the absolute times.
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

import numpy as np

from estimator.damper import CurveBatch, PiecewiseLinearCurve
from estimator.dynamics import CornerPhysics, QuarterCarPhysics, integrate_rk4
from estimator.simulation_kernel import integrate_compiled, kernel_in_use
from estimator.vehicle import TyreModel
from service.kernel_build import compile_ahead

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_TIME_S = 0.001
DURATION_S = 12.0
POPULATION = 20
GRID_POINTS = 20
BASELINE_COMMIT = "67fc87b"  # before issue 15 (no kernel, no lazy imports)


def _plate(rng: np.random.Generator, columns: int | None) -> tuple[np.ndarray, np.ndarray]:
    """A 0.5-20 Hz linear sweep of 4 mm (slightly different per column when `columns` is given)."""
    t = np.arange(round(DURATION_S / SAMPLE_TIME_S) + 1) * SAMPLE_TIME_S
    shape = (columns, 1) if columns else ()
    amplitude = 0.004 * rng.uniform(0.95, 1.05, shape)
    start, stop = 0.5, 20.0
    phase = 2 * np.pi * (start * t + 0.5 * (stop - start) / DURATION_S * t**2)
    rate = amplitude * 2 * np.pi * (start + (stop - start) / DURATION_S * t) * np.cos(phase)
    return amplitude * np.sin(phase), rate


def _forces(rng: np.random.Generator, grid: np.ndarray, columns: int) -> np.ndarray:
    extension = rng.uniform(1200.0, 2500.0, columns)
    slope = np.where(grid[:, None] > 0, extension, 0.5 * extension)
    return slope * np.tanh(3.0 * grid[:, None]) / 3.0


def one_model() -> tuple[QuarterCarPhysics, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    grid = np.linspace(-1.0, 1.0, GRID_POINTS)
    corner = CornerPhysics(
        damper=PiecewiseLinearCurve(grid, _forces(rng, grid, 1)[:, 0]),
        spring_stiffness_N_per_m=25e3,
        tyre_stiffness_N_per_m=200e3,
        tyre_model=TyreModel.MAXWELL,
        tyre_damping_Ns_per_m=1500.0,
        maxwell_time_constant_s=0.004,
    )
    plate, rate = _plate(rng, None)
    return QuarterCarPhysics(corner, 320.0, 40.0), np.zeros(5), plate, rate


def population() -> tuple[QuarterCarPhysics, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(2)
    columns = POPULATION
    grid = np.linspace(-1.0, 1.0, GRID_POINTS)
    some = rng.random((4, columns)) < 0.5
    sprung, unsprung = rng.uniform(300.0, 340.0, columns), rng.uniform(38.0, 42.0, columns)
    corner = CornerPhysics(
        damper=CurveBatch(grid, _forces(rng, grid, columns)),
        spring_stiffness_N_per_m=rng.uniform(24e3, 26e3, columns),
        tyre_stiffness_N_per_m=rng.uniform(190e3, 210e3, columns),
        tyre_model=TyreModel.MAXWELL,
        tyre_damping_Ns_per_m=rng.uniform(1400.0, 1600.0, columns),
        maxwell_time_constant_s=0.004,
        coulomb_friction_N=some[0] * rng.uniform(20.0, 80.0, columns),
        cubic_spring_N_per_m3=some[1] * rng.uniform(1e6, 1e7, columns),
        tyre_liftoff=some[2],
        static_wheel_load_N=(sprung + unsprung) * 9.81,
        tyre_dashpot_Ns_per_m=some[3] * rng.uniform(50.0, 200.0, columns),
    )
    plate, rate = _plate(rng, columns)
    return QuarterCarPhysics(corner, sprung, unsprung), np.zeros((5, columns)), plate, rate


def compare(name: str, case) -> str:
    physics, state0, plate, rate = case
    start = time.perf_counter()
    reference = integrate_rk4(physics.derivatives, state0, SAMPLE_TIME_S, plate, rate)
    python_s = time.perf_counter() - start
    times = []
    for _ in range(7):
        start = time.perf_counter()
        compiled = integrate_compiled(physics, state0, SAMPLE_TIME_S, plate, rate)
        times.append(time.perf_counter() - start)
    kernel_s = statistics.median(times)
    scale = np.maximum(np.max(np.abs(reference), axis=0), 1e-12)
    difference = float(np.max(np.abs(compiled - reference) / scale))
    return (
        f"| {name} | {python_s:.2f} s | {kernel_s * 1e3:.1f} ms | {python_s / kernel_s:.0f}x | "
        f"{difference:.1e} |"
    )


def _fresh_process_s(code: str, cwd: Path, repeats: int) -> float:
    times = []
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, check=True, capture_output=True)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


SCIPY = "import scipy.linalg, scipy.optimize, scipy.signal"
"""What an identify or diagnose process has imported anyway (numba's first call imports scipy.linalg)."""


def kernel_fixed_cost() -> str:
    compile_ahead()  # warm the on-disk cache if this source version was never compiled here
    bare = _fresh_process_s(SCIPY, ROOT, 5)
    imported = _fresh_process_s(f"{SCIPY}; import estimator.simulation_kernel", ROOT, 5)
    loaded = _fresh_process_s(f"{SCIPY}; import estimator.simulation_kernel as k; k.warm()", ROOT, 5)
    return (
        f"fresh process with scipy imported: {bare:.2f} s; + import the kernel module "
        f"{imported - bare:.2f} s; + first call (kernel in use: {kernel_in_use()}; numba loads it from its "
        f"on-disk cache, the extension is imported) {loaded - imported:.2f} s"
    )


HELP = "from service.cli.main import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass"


def help_times(baseline_commit: str) -> list[str]:
    lines = []
    now = _fresh_process_s(HELP, ROOT, 5)
    bare = _fresh_process_s("pass", ROOT, 5)
    with tempfile.TemporaryDirectory() as folder:
        archive = subprocess.run(
            ["git", "archive", baseline_commit], cwd=ROOT, check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
        before = _fresh_process_s(HELP, Path(folder), 5)
    lines.append(f"| `shockbench --help`, this tree | {now:.2f} s | python alone {bare:.2f} s |")
    lines.append(
        f"| `shockbench --help`, {baseline_commit} (before lazy imports) | {before:.2f} s | "
        f"{before / now:.1f}x this tree's time |"
    )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--baseline-commit", default=BASELINE_COMMIT, help="the tree `--help` is compared with"
    )
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.1f} at start"
    )
    compile_ahead()
    print(f"12 s at 1 kHz, {round(DURATION_S / SAMPLE_TIME_S)} RK4 steps; reference once, kernel median of 7")
    print("| simulation | Python integrate_rk4 | compiled kernel | ratio | max relative difference |")
    print("|---|---|---|---|---|")
    print(compare("quarter car, 1 model (identify's gap)", one_model()))
    print(compare(f"quarter car, {POPULATION} models with effects (doctor)", population()))
    print(kernel_fixed_cost())
    print("| process | wall (median of 5) | |")
    print("|---|---|---|")
    for line in help_times(args.baseline_commit):
        print(line)
    print(f"load average {os.getloadavg()[0]:.1f} at end")


if __name__ == "__main__":
    main()
