"""Benchmark: identify in-process with its confidence bands (issue 13's speed target: with free stiffnesses,
< 0.3 s for 12 s at 1 kHz, without the output-error simulation), the bands' cost before and after their
bias allowances were re-solved by Newton steps from the optimum (estimator.newton_refit), side by side.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_identify_inprocess.py [--repeats 7]

The recording: the embedded default quarter car (valve-model damper, Maxwell tyre, 5 µm noise), an 11 s
sweep plus 1 s settling at 1 kHz (12 001 samples); nsample 5000, 20 curve points, exact solver,
IdentifyOptions(output_error=False). Vehicle files: complete, and mass-only (spring, tyre and ϑ identified).
Variants, run in turn within each repeat so that the machine's load falls on all alike (median reported),
each without and with the bands:

- before: the joint ϑ search by IRLS alone to its tolerance (estimator.relaxation.NEWTON_HANDOVER set to 0
  for the run, which is exactly the previous loop), and the bands as they were computed before: the
  sandwich and the two bias allowances re-solved from scratch (IRLS on the refined grid from the
  least-squares point; with the lowered kinematics cutoff the whole ϑ search, or IRLS when ϑ is stated);
- now: identify as it is (IRLS handing over to Newton steps; the allowances by Newton steps from the
  optimum found, estimator.newton_refit).

It also prints the largest difference between the two bands' half-widths, relative (the same bands).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from dataclasses import replace

import numpy as np

from estimator import relaxation
from estimator.equations import build
from estimator.identify import IdentificationResult, IdentifyOptions, identify
from estimator.relaxation import fit_relaxation_time
from estimator.solvers.exact import solve_exact
from estimator.sweep import SweepSettings
from estimator.uncertainty import (
    KINEMATICS_CUTOFF_RATIO,
    KINEMATICS_RICHARDSON,
    Intervals,
    confidence_intervals,
    refined_grids,
    richardson_bias,
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
    bias = richardson_bias(system, theta, fine_system, fine)
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


def run(recording, vehicle: VehicleParameters, label: str, repeats: int) -> float:
    """Prints the table rows of one vehicle file; returns the median of identify with bands, now."""
    quick = IdentifyOptions(output_error=False, intervals=False)
    full = IdentifyOptions(output_error=False)
    reference = identify(recording, vehicle, full)  # warm-up, and θ to carry the old bands on
    handover = relaxation.NEWTON_HANDOVER

    def before(bands: bool):
        relaxation.NEWTON_HANDOVER = 0.0  # IRLS alone, as before
        try:
            result = identify(recording, vehicle, quick)
            return bands_before(recording, result, reference) if bands else result
        finally:
            relaxation.NEWTON_HANDOVER = handover

    variants = {
        "no bands, before": lambda: before(False),
        "no bands, now": lambda: identify(recording, vehicle, quick),
        "bands, before": lambda: before(True),
        "bands, now": lambda: identify(recording, vehicle, full),
    }
    times: dict[str, list[float]] = {name: [] for name in variants}
    values: dict[str, object] = {}
    for _ in range(repeats):
        for name, variant in variants.items():
            seconds, values[name] = timed(variant)
            times[name].append(seconds)
    old_intervals = values["bands, before"]
    assert isinstance(old_intervals, Intervals) and reference.intervals is not None
    change = np.max(np.abs(reference.intervals.half_width / old_intervals.half_width - 1.0))
    for name, values_s in times.items():
        print(f"| {label} | {name} | {statistics.median(values_s):.3f} | {min(values_s):.3f} |")
    print(f"|   | half-widths now vs before: largest relative difference {change:.1e} | | |")
    return statistics.median(times["bands, now"])


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
    print("| vehicle file | identify | median (s) | fastest (s) |")
    print("|---|---|---:|---:|")
    run(recording, known, "complete", args.repeats)
    seconds = run(recording, alone, "mass only", args.repeats)
    verdict = "met" if seconds < TARGET_S else "NOT met"
    print(f"\nmass only, with bands: {seconds:.3f} s; target < {TARGET_S} s: {verdict}")


if __name__ == "__main__":
    main()
