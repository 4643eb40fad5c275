"""Benchmark: identify (default, exact solver) and the project's DE with the paper's settings against
scipy.optimize.differential_evolution with the paper's settings, on the same objective and recording, in one
run so the ratios are measured side by side.

    .venv/bin/python benchmarks/bench_identify.py            # full: 3000 generations for every DE
    .venv/bin/python benchmarks/bench_identify.py --quick    # 300 generations (a smoke run)
    .venv/bin/python benchmarks/bench_identify.py --identify-only   # the identify timings only

First, identify (exact solver, no output-error simulation) on a 12 s recording at 1 kHz (11 s sweep plus
1 s settling) with the complete vehicle file and with a mass-only one (spring, tyre stiffness and ϑ
identified): median of 7 runs, in-process; target < 0.3 s for the mass-only file.

The recording is the embedded default quarter car (valve-model damper, Maxwell tyre, 5 µm noise), a 20 s
sweep; the objective uses nsample = 5000 samples and 20 curve points. scipy runs rand1bin with F = 1,
CR = 0.3, the same 70-member initial population, no polishing, tol = 0 (all generations), its default
"immediate" updating (one call per individual, as scipy's DE is normally used), and also vectorized with
"deferred" updating for reference.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from dataclasses import replace

import numpy as np
from scipy.optimize import differential_evolution

from estimator.equations import build
from estimator.identify import Coordinates, IdentifyOptions, de_problem, identify
from estimator.solvers.differential_evolution import DESettings, DifferentialEvolution
from estimator.solvers.exact import solve_exact
from estimator.sweep import SweepSettings
from estimator.vehicle import TyreModel
from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate, true_damper


def curve_error_percent(theta: np.ndarray, system, truth) -> float:
    grid, points = system.grids_m_s[0], theta[system.curve_slices[0]]
    dense = np.linspace(*np.quantile(system.velocity_m_s[0], [0.005, 0.995]), 400)
    identified = np.interp(dense, grid, points)
    true = truth.force(dense)
    return float(100 * np.sqrt(np.mean((identified - true) ** 2)) / np.max(np.abs(true)))


def timed(fn, repeats: int = 1):
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), value


MASS_ONLY_TARGET_S = 0.3


def bench_mass_only() -> None:
    """identify on 12 s at 1 kHz: complete vehicle file against a mass-only one."""
    vehicle = default_quarter_car()
    recording = simulate(vehicle, SimulationSettings(sweep=SweepSettings(duration_s=11.0), seed=0)).recording
    known = vehicle.known
    alone = replace(
        known, spring_stiffness_N_per_m=None, tyre_stiffness_N_per_m=None, tyre_viscoelastic_coefficient=None
    )
    options = IdentifyOptions(output_error=False)
    identify(recording, alone, options)  # warm-up: imports, filter design caches
    print(
        f"\nidentify, exact solver, {recording.time_s.size} samples "
        f"({recording.sample_time_s * 1e3:g} ms), nsample 5000, 20 points, median of 7:\n"
    )
    print("| vehicle file | time (s) | spring | tyre | relaxation time | sprung mass error |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, stated in (("complete", known), ("mass only", alone)):
        seconds, result = timed(lambda v=stated: identify(recording, v, options), repeats=7)
        found = result.model.vehicle
        print(
            f"| {label} | {seconds:.3f} | {found.spring_stiffness_N_per_m:.0f} N/m | "
            f"{found.tyre_stiffness_N_per_m:.0f} N/m | {found.tyre_relaxation_time_s * 1e3:.2f} ms | "
            f"{100 * (result.model.sprung_mass_kg / vehicle.sprung_mass_kg - 1):+.2f}% |"
        )
        if stated is alone:
            verdict = "met" if seconds < MASS_ONLY_TARGET_S else "NOT met"
            print(f"\nmass-only identify {seconds:.3f} s; target < {MASS_ONLY_TARGET_S} s: {verdict}")
    print(
        f"truth: spring {known.spring_stiffness_N_per_m:.0f} N/m, "
        f"tyre {known.tyre_stiffness_N_per_m:.0f} N/m, "
        f"relaxation time {known.tyre_relaxation_time_s * 1e3:.2f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="300 generations instead of 3000")
    parser.add_argument("--identify-only", action="store_true", help="only the identify timings")
    args = parser.parse_args()
    generations = 300 if args.quick else 3000
    print(
        f"machine: {platform.machine()}, {platform.processor() or 'cpu'}, "
        f"Python {platform.python_version()}, "
        f"numpy {np.__version__}"
    )
    bench_mass_only()
    if args.identify_only:
        return
    vehicle = default_quarter_car()
    recording = simulate(vehicle, SimulationSettings(seed=0)).recording
    truth = true_damper(vehicle.dampers[0])
    known = vehicle.known

    t_identify, result = timed(
        lambda: identify(recording, known, IdentifyOptions(output_error=False)), repeats=5
    )
    t_identify_gap, _ = timed(lambda: identify(recording, known), repeats=1)
    system = build(recording, known, TyreModel.MAXWELL)
    exact = solve_exact(system)
    rows = [
        (
            "identify, exact solver (default; build + solve + tanh fit)",
            t_identify,
            exact.objective,
            exact.theta,
        )
    ]
    print(f"identify with output-error gap simulation: {t_identify_gap:.2f} s")

    settings = DESettings(generations=generations)
    timings = {}
    for coordinates in (Coordinates.DECORRELATED, Coordinates.RAW):
        problem = de_problem(system, known, coordinates)
        solver = DifferentialEvolution(problem.population_objective32(), problem.bounds, settings)
        seconds, res = timed(solver.solve)
        theta = problem.theta(res.theta)
        timings[f"ours-{coordinates.value}"] = seconds
        rows.append(
            (
                f"project DE, paper settings, {coordinates.value} coordinates",
                seconds,
                float(system.objective(theta)),
                theta,
            )
        )
        init = np.random.default_rng(0).uniform(
            problem.bounds[:, 0], problem.bounds[:, 1], (70, system.n_params)
        )
        for mode, kwargs in (("immediate", {}), ("vectorized", {"vectorized": True, "updating": "deferred"})):
            if mode == "vectorized":
                objective = lambda z, p=problem: p.objective(np.asarray(z).T)  # noqa: E731 - scipy's (p, S) layout
            else:
                objective = problem.objective
            seconds, res = timed(
                lambda obj=objective, kw=kwargs, p=problem, i=init: differential_evolution(
                    obj,
                    p.bounds,
                    strategy="rand1bin",
                    mutation=1.0,
                    recombination=0.3,
                    maxiter=generations,
                    init=i,
                    tol=0,
                    atol=0,
                    polish=False,
                    seed=0,
                    **kw,
                )
            )
            theta = problem.theta(res.x)
            timings[f"scipy-{mode}-{coordinates.value}"] = seconds
            rows.append(
                (
                    f"scipy DE ({mode}), paper settings, {coordinates.value} coordinates",
                    seconds,
                    float(system.objective(theta)),
                    theta,
                )
            )

    print(
        f"\n{generations} generations, NP 70, F 1, CR 0.3; nsample 5000, 20 points; exact optimum "
        f"{exact.objective:.6g} (certified gap {100 * exact.certified_gap:.4f}%)\n"
    )
    print("| method | time (s) | objective gap to exact | sprung mass error | curve error (% of peak) |")
    print("|---|---:|---:|---:|---:|")
    for name, seconds, objective, theta in rows:
        gap = (objective - exact.objective) / exact.objective
        mass = 100 * (theta[0] / vehicle.sprung_mass_kg - 1)
        print(
            f"| {name} | {seconds:.3f} | {100 * gap:.4f}% | {mass:+.2f}% | "
            f"{curve_error_percent(theta, system, truth):.2f} |"
        )
    print()
    for coordinates in ("decorrelated", "raw"):
        ours = timings[f"ours-{coordinates}"]
        print(
            f"{coordinates}: scipy immediate / project DE = "
            f"{timings[f'scipy-immediate-{coordinates}'] / ours:.1f}x, scipy vectorized / project DE = "
            f"{timings[f'scipy-vectorized-{coordinates}'] / ours:.1f}x"
        )
    print(
        f"identify (default) {t_identify:.3f} s; target < 0.5 s: {'met' if t_identify < 0.5 else 'NOT met'}"
    )
    del result


if __name__ == "__main__":
    main()
