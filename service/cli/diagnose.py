"""`shockbench diagnose`: the model doctor on a recording (estimator.doctor): where the identified model and
the measurement disagree, which missing effect explains it, the gap before and after adding it."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from estimator.vehicle import TyreModel
from service.cli.errors import CliError
from service.cli.progress import de_progress_line
from service.cli.recording_input import RECORDING_HELP, VEHICLE_HELP, read_recording_and_vehicle
from service.doctor_words import fit_verdict, micrometres, shape

if TYPE_CHECKING:
    from estimator.doctor.diagnose import DiagnoseProgress
    from estimator.doctor.result import DiagnosisResult

DOCTOR_POINTS = {"quarter-car": 30, "axle": 15}
"""estimator.doctor.diagnose's DEFAULT_POINTS (curve points per side), named here so that `--help` does not
import the doctor (tests/service/test_readme_cli.py checks they are the same)."""


def summary(result: DiagnosisResult) -> str:
    """Readable report of a diagnosis."""
    lines = [
        f"starting model: {', '.join(result.starting_effects) or 'spring tyre, nothing else'} "
        f"beyond the vehicle file",
        f"gap before: {micrometres(result.gap_before_m)} (sensor noise {micrometres(result.noise_floor_m)})",
        f"where: {result.located_before.describe()}",
    ]
    for number, step in enumerate(result.steps, start=1):
        lines += [
            f"\nstep {number}: {step.effect} (p = {step.p_value:.2g}): {shape(step.effect, step.parameters)}",
            f"  gap {micrometres(step.gap_before_m)} -> {micrometres(step.gap_after_m)}",
            f"  evidence: {step.evidence}",
        ]
    if result.steps:  # a family named early is fitted again beside the later ones: its values may move
        lines.append("\nthe final model, each family named fitted beside the others:")
        lines += [f"  {name}: {shape(name, values)}" for name, values in result.final_parameters.items()]
    lines += [
        f"\ngap after: {micrometres(result.gap_after_m)}; the final model re-identified on synthetic "
        f"recordings of itself with this recording's noise reaches {micrometres(result.expected_gap_m)}",
        f"goodness of fit: {fit_verdict(result.p_value, result.alpha, result.unexplained, result.where)}",
        f"conclusion: {result.conclusion}",
    ]
    if result.refit is not None:
        lines.append(
            f"model (--json): the final one with its curve refined on the free-simulation gap, as something "
            f"it lacks biases the equations' fit: gap {micrometres(result.refit[1])}"
        )
    return "\n".join(lines)


def _progress(p: DiagnoseProgress) -> None:
    """Each stage on a line of its own; a DE's generations within a stage (the refinement that ends a
    diagnosis: seconds on most recordings, minutes on a sharp friction step) on one line, redrawn."""
    if p.generation is not None:
        de_progress_line(f"diagnose: step {p.step}: {p.stage}", p.generation)
        return
    sys.stderr.write(f"diagnose: step {p.step}: {p.stage}\n")
    sys.stderr.flush()


def run_diagnose(args: argparse.Namespace) -> int:
    from estimator.doctor.diagnose import DiagnoseOptions
    from estimator.identify import check_curve_points
    from service.analysis import diagnose_recording

    report = Path(args.report) if args.report else None
    if report is not None and report.exists() and not report.is_dir():
        raise CliError(f"--report {report}: exists and is not a folder")
    recording, vehicle = read_recording_and_vehicle("diagnose", args.recording, args.vehicle)
    check_curve_points(args.points, "--points")  # identify's limits, as the diagnose job's options
    options = DiagnoseOptions(tyre=TyreModel(args.tyre), points=args.points)
    # the job's submit check first (bad input: one line, exit 2)
    result = diagnose_recording(recording, vehicle, options, progress=None if args.json else _progress)
    if report is not None:
        from service.doctor_report import write_report  # matplotlib: only for a report (0.3-1 s to import)

        path = write_report(result, report, title=Path(args.recording).name)
        if not args.json:
            print(f"report: {path}", file=sys.stderr)
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        print(summary(result))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "diagnose",
        help="find what the identified model lacks, name it, add it and show the gap shrink",
        description="The model doctor: simulate the identified model from the measured plate, locate where "
        "it disagrees with the measured x_s and x_t, test every effect family of the catalog (a Wald test "
        "of its unknowns and a likelihood ratio of the gap), name the most significant one when it passes "
        "a family-wise error rate of 5%, add it and repeat; then test the final model against bootstrap "
        "draws of itself with the recording's own noise and say 'unexplained', and where, when p < 5%.",
    )
    p.add_argument("recording", help=RECORDING_HELP)
    p.add_argument("--vehicle", default=None, help=VEHICLE_HELP)
    p.add_argument(
        "--tyre",
        choices=[t.value for t in TyreModel],
        default="maxwell",
        help="tyre of the starting model (default maxwell)",
    )
    p.add_argument(
        "--points",
        type=int,
        default=None,
        help=f"curve points (default {DOCTOR_POINTS['quarter-car']}, axle {DOCTOR_POINTS['axle']} per side: "
        "1.5 times identify's, as 20 cannot follow a real damper's knee)",
    )
    p.add_argument("--report", default=None, help="folder for report.md and its PNG plots")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=run_diagnose)
