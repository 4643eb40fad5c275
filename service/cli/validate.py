"""`shockbench validate`: cross-validation of an identified model on another recording of the same vehicle
(estimator.validation): the gap between the model driven by that recording's plate and its measured body
and wheel motion, absolute and relative to the motion."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.cli.errors import CliError
from service.cli.recording_input import RECORDING_HELP, load_recording

if TYPE_CHECKING:
    from estimator.validation import ValidationResult


def read_model_json(path: Path) -> dict[str, Any]:
    """The JSON object of a model file (identify --json output); CliError in one line."""
    if not path.is_file():
        raise CliError(f"{path}: no such file")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise CliError(f"{path}: not a text file (UTF-8 expected)") from None
    except json.JSONDecodeError as exc:
        raise CliError(f"{path}: not JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(data, dict):
        raise CliError(f"{path}: expected a JSON object (the output of identify --json or diagnose --json)")
    return data


def summary(result: ValidationResult) -> str:
    gap = f"{result.gap_m * 1e6:.1f} µm RMS" if math.isfinite(result.gap_m) else "diverged"
    ratio = f"{100 * result.gap_ratio:.2f}%" if math.isfinite(result.gap_ratio) else "-"
    effects = ", ".join(result.effects) or "none"
    return (
        f"gap {gap} (model driven by this recording's plate against its measured body and wheel)\n"
        f"measured body and wheel motion {result.response_rms_m * 1e6:.1f} µm RMS\n"
        f"gap ratio {ratio} of the motion\n"
        f"effects beyond identify's model, simulated: {effects}"
    )


def run_validate(args: argparse.Namespace) -> int:
    from estimator.model_io import model_from_json
    from estimator.validation import validate

    if args.track_m is not None and not args.track_m > 0:
        raise CliError("--track-m must be > 0")
    model = model_from_json(read_model_json(Path(args.model)), track_m=args.track_m)
    recording = load_recording("validate", args.recording).recording
    result = validate(model, recording)
    print(json.dumps(result.to_json()) if args.json else summary(result))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="cross-validate an identified model on another recording of the same vehicle",
        description="Simulate the model of RESULT.json (the output of identify --json, or of diagnose "
        "--json: its final model with every effect named) driven by the recording's plate motion and "
        "compare with its measured body and wheel motion: gap_m, response_rms_m and gap_ratio = gap / "
        "response.",
    )
    p.add_argument("recording", help=f"{RECORDING_HELP} (any sample rate and length)")
    p.add_argument("--model", required=True, help="JSON from identify --json or diagnose --json")
    p.add_argument(
        "--track-m",
        type=float,
        default=None,
        help="wheel track (m) of an axle model: overrides the file's track_m (needed for files "
        "written before identify stated it)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=run_validate)
