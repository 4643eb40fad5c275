"""Experiment (issue 29, item 5): what takes the unrecorded force's bias out of a mass-only identification
on the lab rig world, identify's output-error refinement (`identify --refine`) or instrumental variables?
Not a feature: measured leads for the next design.

    PYTHONPATH=. OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_lab_rig_instruments.py --rigs 24

Why: on the lab rigs (simulators/lab_rig) a force no file records (the lab's voice coil and its controller)
acts between body and wheel. It is in every equation's residual and it moves the body and the wheel, so the
measured motions the equations are built from are correlated with the residual: least squares (and
identify's sum of norms) are biased, and a bias fitted on run A does not transfer to run B. Instruments that
the unrecorded force does not move, but that follow the regressors, remove that bias: here the same
equation columns built from the motion the identified model itself simulates from the measured plate (the
plate's chirp is independent of the coil's command). One pass: θ from (Zᵀ A) θ = −Zᵀ c, Z those columns, A
and c identify's system (estimator.equations.LinearResiduals, every equation and selected sample a row),
the tyre's ϑ kept at identify's, no constraint on the curve.

For each rig of the set (simulators/lab_rig; `--set dev`: seeds 0-999, which may be looked at; `--set
held-out --offset N`: bench_lab_rig.py's frozen seeds from 200000 + N, for scoring a design made on DEV rigs)
runs A and B are simulated as bench_lab_rig.py does (`--cache` shares its files), and printed: mass-only
identify's held-out gap (its model from run A validated on run B, % of B's response RMS), that of identify
with `refine_output_error` (DE over the curve points and the tyre damping on run A's free-simulation gap,
estimator.output_error.refine_on_output_error: an output-error fit is not biased by the part of a
disturbance the plate does not cause) and the instrumental-variable model's, in-sample and held-out, with
the rates against the truth. A model that cannot be simulated (a rate not positive) is reported as such.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_lab_rig import DEV_SEEDS, HELD_OUT_SEEDS, rig_files

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from estimator.damper import PiecewiseLinearCurve
from estimator.equations import TYRE_DAMPING, LinearResiduals, build
from estimator.errors import UserError
from estimator.identify import IdentifyOptions, constants_to_identify, identify
from estimator.output_error import IdentifiedModel, simulate_identified
from estimator.recording import Recording
from estimator.validation import validate


def rows(system: LinearResiduals) -> tuple[np.ndarray, np.ndarray]:
    """The system as (rows, unknowns) and its offset: residual = matrix·θ + offset."""
    equations, samples, unknowns = system.matrix.shape
    matrix = system.matrix.transpose(1, 0, 2).reshape(samples * equations, unknowns)
    return matrix, system.offset.T.reshape(samples * equations)


def model_of(start: IdentifiedModel, system: LinearResiduals, theta: np.ndarray) -> IdentifiedModel:
    """identify's model with θ's curve, sprung mass, tyre damping and free rates (a rate not positive:
    UserError, as identify says it)."""
    changes = {}
    for name in ("spring_stiffness_N_per_m", "tyre_stiffness_N_per_m"):
        value = system.value(theta, name)
        if value is not None:
            if not value > 0:
                raise UserError(f"{name} {value:.4g} not positive")
            changes[name] = value
    curves = tuple(
        PiecewiseLinearCurve(grid, theta[part])
        for grid, part in zip(system.grids_m_s, system.curve_slices, strict=True)
    )
    return replace(
        start,
        vehicle=replace(start.vehicle, **changes),
        curves=curves,
        sprung_mass_kg=float(theta[0]),
        tyre_damping_Ns_per_m=system.value(theta, TYRE_DAMPING) or 0.0,
    )


def instrumented(
    run_a: Recording, fitted_model: IdentifiedModel, system: LinearResiduals, unknown: frozenset
):
    """One instrumental-variable pass from identify's model (module docstring)."""
    options = IdentifyOptions()
    simulated = simulate_identified(fitted_model, run_a, system.kinematics, system.filters.noise_floor_m)
    channels = {**run_a.channels, **{name: np.asarray(x) for name, x in simulated.simulated.items()}}
    motion = Recording(run_a.time_s, channels, dict(run_a.metadata))
    instruments = build(
        motion,
        fitted_model.vehicle,
        options.tyre,
        None,
        options.nsample,
        system.filters,
        system.grids_m_s,
        unknown,
    )
    if system.tyre_theta is not None:
        instruments = instruments.with_tyre_theta(system.tyre_theta)
    matrix, offset = rows(system)
    z, _ = rows(instruments)
    theta = np.linalg.lstsq(z.T @ matrix, -(z.T @ offset), rcond=None)[0]
    return model_of(fitted_model, system, theta)


def percent(value: float) -> str:
    return f"{100.0 * value:.0f}%" if np.isfinite(value) else "diverged"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--set", choices=("dev", "held-out"), default="dev")
    parser.add_argument("--rigs", type=int, default=12, help="this many rigs of the set")
    parser.add_argument("--offset", type=int, default=0, help="skip this many rigs of the set first")
    parser.add_argument("--run-s", type=float, default=16.0)
    parser.add_argument("--cache", default=None, help="folder of the rigs' runs (bench_lab_rig.py's --cache)")
    args = parser.parse_args()
    folder = args.cache or tempfile.mkdtemp(prefix="lab-rig-iv-")
    Path(folder).mkdir(parents=True, exist_ok=True)
    held: dict[str, list[float]] = {"identify": [], "identify --refine": [], "instrumented": []}
    print("| rig | identify | --refine (in-sample) | instrumented (in-sample) | rates: identify, IV, true |")
    print("|---|---:|---:|---:|---|")
    seeds = DEV_SEEDS if args.set == "dev" else HELD_OUT_SEEDS
    for seed in list(seeds)[args.offset : args.offset + args.rigs]:
        draw, files, _ = rig_files(seed, folder, args.run_s)
        run_a, run_b = read_recording_csv(files["A"].csv), read_recording_csv(files["B"].csv)
        vehicle = read_vehicle(files["A"].mass_only_toml)
        result = identify(run_a, vehicle, IdentifyOptions())
        unknown = constants_to_identify(vehicle, IdentifyOptions())
        base = validate(result.model, run_b).gap_ratio
        held["identify"].append(base)
        refined = identify(run_a, vehicle, IdentifyOptions(refine_output_error=True)).model
        refined_out = validate(refined, run_b).gap_ratio
        held["identify --refine"].append(refined_out)
        oe = f"{percent(refined_out)} ({percent(validate(refined, run_a).gap_ratio)})"
        v = result.model.vehicle
        rates = f"{v.spring_stiffness_N_per_m:.0f}/{v.tyre_stiffness_N_per_m:.0f}"
        try:
            model = instrumented(run_a, result.model, result.system, unknown)
            out, inside = validate(model, run_b).gap_ratio, validate(model, run_a).gap_ratio
            iv = f"{percent(out)} ({percent(inside)})"
            rates += (
                f", {model.vehicle.spring_stiffness_N_per_m:.0f}/{model.vehicle.tyre_stiffness_N_per_m:.0f}"
            )
        except UserError as exc:
            out, iv = float("inf"), f"no model: {exc}"
        held["instrumented"].append(out)
        truth = f"{draw.rig.spring_N_per_m:.0f}/{draw.rig.tyre_N_per_m:.0f}"
        print(f"| {seed} | {percent(base)} | {oe} | {iv} | {rates}, {truth} |", flush=True)
    for name, gaps in held.items():
        finite = [g for g in gaps if np.isfinite(g)]
        within = sum(g <= 0.40 for g in gaps)
        median = statistics.median(gaps) if finite else float("nan")
        print(f"{name}: held-out ≤ 40% on {within}/{len(gaps)}, median {percent(median)}")


if __name__ == "__main__":
    main()
