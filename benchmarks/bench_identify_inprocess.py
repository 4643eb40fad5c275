"""Benchmark: identify in-process with its confidence bands (issue 13's speed target: with free stiffnesses,
< 0.3 s for 12 s at 1 kHz, without the output-error simulation), the bands' cost before and after their
bias allowances were re-solved by Newton steps from the optimum (estimator.newton_refit), side by side.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_identify_inprocess.py [--repeats 7]

The recording: the embedded default quarter car (valve-model damper, Maxwell tyre, 5 µm noise), an 11 s
sweep plus 1 s settling at 1 kHz (12 001 samples); nsample 5000, 20 curve points, exact solver,
IdentifyOptions(output_error=False). Vehicle files: complete, and mass-only (spring, tyre and ϑ identified).
Variants, run in turn within each repeat so that the machine's load falls on all alike (median reported):

- no bands: IdentifyOptions(intervals=False);
- bands, before: identify without bands plus the bands as they were computed before (the sandwich, and the
  two bias allowances re-solved from scratch: IRLS on the refined grid from the least-squares point, and
  with the lowered kinematics cutoff the full ϑ search of estimator.relaxation, or IRLS when ϑ is stated);
- bands, now: identify as it is (the allowances by Newton steps from the optimum found).

It also prints the largest difference between the two bands' half-widths, relative (the same bands).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from dataclasses import replace

import numpy as np

from drivers.exciter.sweep import SweepSettings
from estimator.equations import build
from estimator.identify import IdentificationResult, IdentifyOptions, identify
from estimator.relaxation import fit_relaxation_time
from estimator.solvers.exact import solve_exact
from estimator.uncertainty import (
    KINEMATICS_CUTOFF_RATIO,
    KINEMATICS_RICHARDSON,
    RICHARDSON_FACTOR,
    Intervals,
    confidence_intervals,
    refined_grids,
)
from estimator.vehicle import VehicleConstant, VehicleParameters
from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate

TARGET_S = 0.3


def bands_before(recording, result: IdentificationResult, reference: IdentificationResult) -> Intervals:
    """The bands as estimator.uncertainty computed them before the Newton re-solves (commit 3a8451b), for
    the identification `result` (reference: the same with bands, for θ in the system's unknowns)."""
    system, vehicle = result.system, result.model.vehicle
    theta = system_theta(reference)
    free_theta = VehicleConstant.THETA in result.identified
    intervals = confidence_intervals(system, theta, recording.sample_time_s, free_theta)
    unknown = result.identified
    tyre = result.model.tyre_model
    fine_system = build(recording, vehicle, tyre, None, 5000, system.filters, refined_grids(system), unknown)
    fine = solve_exact(fine_system, tolerance=1e-9, initial=None, certify=False).theta
    bias = np.zeros(system.n_params)
    in_curves = np.zeros(system.n_params, bool)
    for coarse, fine_slice in zip(system.curve_slices, fine_system.curve_slices, strict=True):
        bias[coarse] = RICHARDSON_FACTOR * np.abs(theta[coarse] - fine[fine_slice][::2])
        in_curves[coarse] = True
    for index, name in enumerate(system.parameter_names):
        if not in_curves[index]:
            matching = fine[fine_system.parameter_names.index(name)]
            bias[index] = RICHARDSON_FACTOR * abs(theta[index] - matching)
    cutoff = system.filters.kinematics_cutoff_Hz * KINEMATICS_CUTOFF_RATIO
    lower = replace(system.filters, kinematics_cutoff_Hz=cutoff)
    smoother = build(recording, vehicle, tyre, None, 5000, lower, system.grids_m_s, unknown)
    other = (
        fit_relaxation_time(smoother).solution.theta
        if free_theta
        else solve_exact(smoother, certify=False).theta
    )
    bias = np.hypot(bias, KINEMATICS_RICHARDSON * np.abs(theta - other))
    return intervals.with_bias(bias)


def system_theta(result: IdentificationResult) -> np.ndarray:
    """θ of the identification, in its system's unknowns (the bands are centred on it)."""
    assert result.intervals is not None
    return result.intervals.theta


def timed(fn):
    start = time.perf_counter()
    value = fn()
    return time.perf_counter() - start, value


def run(recording, vehicle: VehicleParameters, label: str, repeats: int) -> None:
    quick = IdentifyOptions(output_error=False, intervals=False)
    full = IdentifyOptions(output_error=False)
    reference = identify(recording, vehicle, full)  # warm-up, and θ to carry the old bands on
    times: dict[str, list[float]] = {"no bands": [], "bands, before": [], "bands, now": []}
    for _ in range(repeats):
        seconds, _ = timed(lambda: identify(recording, vehicle, quick))
        times["no bands"].append(seconds)
        seconds, old = timed(lambda: bands_before(recording, identify(recording, vehicle, quick), reference))
        times["bands, before"].append(seconds)
        seconds, _ = timed(lambda: identify(recording, vehicle, full))
        times["bands, now"].append(seconds)
    old_intervals = old
    assert reference.intervals is not None
    change = np.max(np.abs(reference.intervals.half_width / old_intervals.half_width - 1.0))
    medians = {name: statistics.median(values) for name, values in times.items()}
    base = medians["no bands"]
    for name, seconds in medians.items():
        print(f"| {label} | {name} | {seconds:.3f} | {seconds / base:.2f}x |")
    print(f"|   | half-widths now vs before: largest relative difference {change:.1e} | | |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {platform.processor() or 'cpu'}, "
        f"Python {platform.python_version()}, numpy {np.__version__}; "
        f"median of {args.repeats}, variants interleaved"
    )
    car = default_quarter_car()
    recording = simulate(car, SimulationSettings(sweep=SweepSettings(duration_s=11.0), seed=0)).recording
    known = car.known
    alone = replace(
        known, spring_stiffness_N_per_m=None, tyre_stiffness_N_per_m=None, tyre_viscoelastic_coefficient=None
    )
    print(f"{recording.time_s.size} samples at {recording.sample_time_s * 1e3:g} ms\n")
    print("| vehicle file | identify | time (s) | vs no bands |")
    print("|---|---|---:|---:|")
    run(recording, known, "complete", args.repeats)
    run(recording, alone, "mass only", args.repeats)
    print(f"\ntarget (mass only, with bands): < {TARGET_S} s")


if __name__ == "__main__":
    main()
