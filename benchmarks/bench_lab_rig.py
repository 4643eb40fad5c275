"""Benchmark: the model doctor and mass-only identification on the lab quarter-car rig world (issue 29,
item 5; simulators/lab_rig): light rigs whose data sheet states the spring and tyre rates 40-80% off and
whose body and wheel feel a force no file records (a voice coil run by the lab's controller, its cogging,
its cable's drag), friction of their own and bearing friction, read at 500 Hz by 2-10 µm lasers.

    .venv/bin/python benchmarks/bench_lab_rig.py --set held-out --rigs 10 --jobs 2
    .venv/bin/python benchmarks/bench_lab_rig.py --set dev --rigs 3 --cache /tmp/lab-rig

Seeds. Two ranges, kept apart: DEV_SEEDS (0-999) may be looked at while designing the doctor; HELD_OUT_SEEDS
(200000-200999) are frozen and count for the figures only, never for tuning (`--set held-out` runs the
first `--rigs` of them after `--offset`; 100000-100999, seen once before the world's last change, are
retired). 200000-200099 have been scored (2026-11-27/28, BENCHMARKS.md): a doctor designed after that is
scored, for rigs no design has followed, from 200100 on (`--offset 100`). Dev rigs
0-9 set the coil's strength (simulators/lab_rig/draws.py).

For every rig (simulators.lab_rig.draws.draw_rig) runs A (0-20 Hz chirp) and B (random road) are simulated
and written as recording CSV with the vehicle file stating the wrong rates (A.toml) and a mass-only file
(A.mass-only.toml), read back with the project's readers (daq.formats), and:

(a) the doctor (estimator.doctor.diagnose, as `shockbench diagnose` with its default Maxwell tyre) runs on
    run A from the stated rates: what it names (the rates it corrects to, against the truth), its verdict,
    its gap before and after as % of the response RMS of run A, and where it locates what remains;
(b) the doctor's final model (its `model` JSON, as `shockbench validate --model` reads it: refined on the
    free-simulation gap when the verdict is "unexplained", docs/method.md) is validated on run B
    (estimator.validation.validate): the held-out gap as % of run B's response RMS;
(c) `identify` on run A from the mass-only file (every rate and ϑ free; estimator.identify, the call of
    `shockbench identify`), its model validated on run B: held-out gap %; and the same with its
    output-error refinement (`shockbench identify --refine`);
(d) each model's damper curve against the rig's own damper (viscous and its guide's friction,
    LabRig.damper_force_N) over run A's excited suspension rates, % of the damper's peak: what a user reads
    the curve as;
(e) two ceilings from the truth, no estimate involved: the part of run B no model driven by the recorded
    plate can predict (unpredictable_percent), and run B as the rig's own physics without the unrecorded
    force simulates it (own_physics_percent), what a model right in every constant would score.

The response RMS is validate's: the RMS of the measured body and wheel motion about their means. Issue 29
asks: the doctor names the rate corrections, its held-out gap is at most 40%, what remains is reported
unexplained and located; mass-only identify's held-out gap is at most 40%.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import tempfile
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimator"))

from cases import PointwiseForce, curve_error_percent  # the tests' measure of a curve against the truth
from lab_rig_outcomes import RATE_EFFECTS, Outcome, named_text, outcome_from_json, percent_cell, print_report

from simulators.lab_rig.draws import RigDraw, draw_rig
from simulators.lab_rig.signals import Still
from simulators.lab_rig.world import RunFiles, simulate_run, write_run

DEV_SEEDS = range(0, 1000)
HELD_OUT_SEEDS = range(200_000, 201_000)
"""Frozen. 100000-100999 were the first held-out range, retired: one run on them came before the world's
last change (the coil's strength), so they are no longer unseen."""
"""Frozen: never looked at while designing. Only these count for the published figures."""


def _percent(value: float) -> float | None:
    return 100.0 * value if math.isfinite(value) else None


def rig_files(seed: int, folder: str, run_s: float) -> tuple[RigDraw, dict[str, RunFiles], float]:
    """Rig `seed` and its runs A and B written in `folder` (read from there when a --cache folder has them),
    with the simulation's wall time (s)."""
    draw = draw_rig(seed, run_s=run_s)
    stems = {name: Path(folder) / f"lab_rig_{seed}_{run_s:g}s_{name}" for name in "AB"}
    facts_path = Path(folder) / f"lab_rig_{seed}_{run_s:g}s.json"
    if facts_path.exists():
        files = {
            name: RunFiles(b.with_suffix(".csv"), b.with_suffix(".toml"), b.with_suffix(".mass-only.toml"))
            for name, b in stems.items()
        }
        return draw, files, float(json.loads(facts_path.read_text())["simulate_s"])
    start = time.perf_counter()
    files = {
        name: write_run(draw.simulate(name), draw.rig, folder, stem.name) for name, stem in stems.items()
    }
    simulate_s = time.perf_counter() - start
    facts_path.write_text(json.dumps({"simulate_s": simulate_s}))
    return draw, files, simulate_s


def unpredictable_percent(draw: RigDraw, measured_b: dict[str, np.ndarray]) -> float:
    """Run B simulated without the coil's reference command (the experiment's own, recorded nowhere: no
    model driven by the recorded plate can predict the motion it causes), against run B as measured, as %
    of B's response RMS (validate's gap over its response: body and wheel pooled). A floor of the held-out
    gap up to what the rest of the coil's force (its skyhook feedback, cogging, the cable), which depends on
    the motion, lets a model take up."""
    spec = replace(draw.run("B"), reference=Still())
    without = simulate_run(draw.rig, spec, draw.noise, draw.sample_time_s).recording.true
    return _gap_percent(measured_b, without)


def own_physics_percent(draw: RigDraw, measured_b: dict[str, np.ndarray]) -> float:
    """Run B simulated by the rig's true physics without the force no file records (coil, cogging, cable:
    the rig as its data sheet imagines it, with the true rates, damper, tyre and bearings), noise-free,
    against run B as measured, as % of B's response RMS. What the best model of the rig itself (every
    constant right, nothing of the unrecorded force) would score held out: where it is above 40%, item 5's
    bound asks a model to take up part of that force, which no vehicle model can do on another run."""
    without = simulate_run(draw.rig, draw.run("B"), draw.noise, draw.sample_time_s, unrecorded=False)
    return _gap_percent(measured_b, without.recording.true)


def _gap_percent(measured: dict[str, np.ndarray], simulated: dict[str, np.ndarray]) -> float:
    """validate's gap over its response (body and wheel pooled), in %."""
    names = ("x_s", "x_t")
    gap = np.sqrt(np.mean([np.mean(np.square(measured[n] - simulated[n])) for n in names]))
    response = np.sqrt(np.mean([np.var(measured[n]) for n in names]))
    return float(100.0 * gap / response)


def _where(located: object) -> str:
    """The doctor's localisation in one sentence (estimator.doctor.residuals.Localisation.describe)."""
    try:
        return located.describe()  # type: ignore[attr-defined]
    except Exception as exc:  # a localisation that cannot describe itself is reported, not fatal
        return f"(no localisation: {exc})"


def run_rig(seed: int, folder: str, run_s: float) -> Outcome:
    """Simulate (or read), then (a), (b), (c) of the module docstring for one rig (in a worker process)."""
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.doctor import DiagnoseOptions, diagnose
    from estimator.doctor.catalog import labels_in
    from estimator.identify import IdentifyOptions, identify
    from estimator.model_io import model_from_json
    from estimator.validation import validate
    from estimator.vehicle import TyreModel

    draw, files, simulate_s = rig_files(seed, folder, run_s)
    a, b = files["A"], files["B"]
    run_a, run_b = read_recording_csv(a.csv), read_recording_csv(b.csv)
    rig = draw.rig
    common = {
        "seed": seed,
        "description": draw.describe(),
        "true_spring_N_per_m": rig.spring_N_per_m,
        "true_tyre_N_per_m": rig.tyre_N_per_m,
        "stated_spring_N_per_m": rig.spring_N_per_m * rig.stated_spring_factor,
        "stated_tyre_N_per_m": rig.tyre_N_per_m * rig.stated_tyre_factor,
        "simulate_s": simulate_s,
        "unrecorded_percent": unpredictable_percent(draw, run_b.channels),
        "own_physics_percent": own_physics_percent(draw, run_b.channels),
    }
    errors = []
    doctor: dict[str, object] = {
        "named": (),
        "rates_named": {},
        "rates_at_step": {},
        "unexplained": False,
        "conclusion": "",
        "located": "",
        "doctor_before_percent": None,
        "doctor_after_percent": None,
        "doctor_heldout_percent": None,
    }
    doctor_model = None
    start = time.perf_counter()
    try:
        result = diagnose(run_a, read_vehicle(a.vehicle_toml), DiagnoseOptions(tyre=TyreModel.MAXWELL))
        data = result.to_json()
        doctor_model = model = model_from_json(data)
        in_sample, held_out = validate(model, run_a), validate(model, run_b)
        response = in_sample.response_rms_m
        at_step = {
            effect: float(step.parameters[RATE_EFFECTS[effect][1]])
            for step in result.steps
            for effect in labels_in(step.effect)  # the load path's families named together: each
            if effect in RATE_EFFECTS
        }
        rates = {  # the corrections the model handed out (and validated on B) holds
            effect: float(values[RATE_EFFECTS[effect][1]])
            for effect, values in result.final_parameters.items()
            if effect in RATE_EFFECTS
        }
        doctor = {
            "named": tuple(result.effects_named),
            "rates_named": rates,
            "rates_at_step": at_step,
            "unexplained": bool(result.unexplained),
            "conclusion": result.conclusion,
            "located": _where(result.located_after),
            "doctor_before_percent": _percent(result.gap_before_m / response),
            "doctor_after_percent": _percent(result.gap_after_m / response),
            "doctor_heldout_percent": _percent(held_out.gap_ratio),
        }
    except Exception as exc:
        errors.append(f"doctor: {type(exc).__name__}: {exc}")
        traceback.print_exc()
    doctor_s = time.perf_counter() - start
    identified: dict[str, object] = {
        "mass_only_in_sample_percent": None,
        "mass_only_heldout_percent": None,
        "mass_only_rates_N_per_m": None,
        "mass_only_refined_heldout_percent": None,
    }
    truth = PointwiseForce(rig.damper_force_N)  # the rig's own damper
    rates_m_s = None
    start = time.perf_counter()
    try:
        fitted = identify(run_a, read_vehicle(a.mass_only_toml), IdentifyOptions())
        model = model_from_json(fitted.to_json())
        vehicle = fitted.model.vehicle
        rates_m_s = fitted.system.velocity_m_s[0]  # run A's suspension rate, as the equations saw it
        identified = {
            "mass_only_in_sample_percent": _percent(validate(model, run_a).gap_ratio),
            "mass_only_heldout_percent": _percent(validate(model, run_b).gap_ratio),
            "mass_only_rates_N_per_m": (vehicle.spring_stiffness_N_per_m, vehicle.tyre_stiffness_N_per_m),
            "mass_only_curve_percent": curve_error_percent(model.curves[0], truth, rates_m_s),
        }
        if doctor_model is not None:
            identified["doctor_curve_percent"] = curve_error_percent(doctor_model.curves[0], truth, rates_m_s)
    except Exception as exc:
        errors.append(f"identify: {type(exc).__name__}: {exc}")
        traceback.print_exc()
    identify_s = time.perf_counter() - start
    try:
        refined = identify(run_a, read_vehicle(a.mass_only_toml), IdentifyOptions(refine_output_error=True))
        refined_model = model_from_json(refined.to_json())
        identified["mass_only_refined_heldout_percent"] = _percent(validate(refined_model, run_b).gap_ratio)
        if rates_m_s is not None:
            identified["mass_only_refined_curve_percent"] = curve_error_percent(
                refined_model.curves[0], truth, rates_m_s
            )
    except Exception as exc:
        errors.append(f"identify --refine: {type(exc).__name__}: {exc}")
        traceback.print_exc()
    return Outcome(
        **common,  # type: ignore[arg-type]
        **doctor,  # type: ignore[arg-type]
        **identified,  # type: ignore[arg-type]
        doctor_s=doctor_s,
        identify_s=identify_s,
        error="; ".join(errors),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", choices=("dev", "held-out"), default="dev", help="which seed range")
    parser.add_argument("--rigs", type=int, default=3, help="rigs: the first N seeds of the range")
    parser.add_argument("--offset", type=int, default=0, help="skip this many seeds of the range first")
    parser.add_argument(
        "--run-s", type=float, default=16.0, help="input length of each run (s), + 1 s settling"
    )
    parser.add_argument("--jobs", type=int, default=1, help="worker processes")
    parser.add_argument("--cache", default=None, help="folder that keeps the simulated runs for re-runs")
    parser.add_argument("--results", default=None, help="append each rig's outcome to this file (JSON lines)")
    parser.add_argument("--from-results", default=None, help="print the report of a --results file only")
    args = parser.parse_args()
    if args.from_results:
        rows = [json.loads(line) for line in Path(args.from_results).read_text().splitlines() if line]
        print_report(sorted((outcome_from_json(r) for r in rows), key=lambda o: o.seed))
        return
    seeds = DEV_SEEDS if args.set == "dev" else HELD_OUT_SEEDS
    if not (args.rigs > 0 and args.offset >= 0 and args.offset + args.rigs <= len(seeds)):
        parser.error(f"--rigs must be 1-{len(seeds) - args.offset}")
    chosen = list(seeds[args.offset : args.offset + args.rigs])
    print(
        f"machine: {platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}; "
        f"{args.set} seeds {chosen[0]}-{chosen[-1]}, {args.jobs} jobs, "
        f"runs of {args.run_s:g} s + 1 s at 500 Hz"
    )
    start = time.perf_counter()
    if args.cache:
        Path(args.cache).mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="lab-rig-") as temporary, ProcessPoolExecutor(args.jobs) as pool:
        folder = args.cache or temporary
        futures = [pool.submit(run_rig, seed, folder, args.run_s) for seed in chosen]
        for done, future in enumerate(as_completed(futures), start=1):
            o = future.result()
            print(
                f"[{done}/{len(chosen)}] rig {o.seed}: {named_text(o)}; held-out doctor "
                f"{percent_cell(o.doctor_heldout_percent)}, "
                f"mass-only {percent_cell(o.mass_only_heldout_percent)}",
                file=sys.stderr,
            )
            if args.results:
                with open(args.results, "a") as handle:
                    handle.write(json.dumps(asdict(o)) + "\n")
        outcomes = sorted((f.result() for f in futures), key=lambda o: o.seed)
    print_report(outcomes)
    print(f"total wall time {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
