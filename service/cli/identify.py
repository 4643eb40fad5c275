"""`shockbench identify`, `shockbench fit-tanh` and `shockbench demo`."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from estimator.solvers.de_settings import DESettings
from estimator.vehicle import TyreModel, VehicleConstant, VehicleParameters
from service.cli.declared import add_options, options, values
from service.cli.errors import CliError
from service.cli.progress import de_progress_line
from service.cli.recording_input import RECORDING_HELP, VEHICLE_HELP, read_recording_and_vehicle

SOLVERS = ("exact", "de")
"""estimator.identify.Solver's values, named here so that `shockbench --help` does not import the estimator
(tests/service/test_cli_lazy_imports.py checks they are the same)."""

DE_OPTIONS = options(DESettings, ("generations", "seed"))
"""--generations and --seed: DESettings' declarations (estimator.solvers.de_settings)."""

if TYPE_CHECKING:
    import numpy as np

    from estimator.identify import IdentificationResult, IdentifyOptions


def summary(result: IdentificationResult) -> str:
    """Readable report of an identification."""
    import numpy as np

    m = result.model
    lines = [
        f"model: {m.vehicle.model.value}, tyre: {m.tyre_model.value}, solver: {result.solver.value}",
        f"sprung mass {m.sprung_mass_kg:.1f} kg, unsprung mass {m.unsprung_mass_kg:.1f} kg per wheel"
        + (f", roll inertia {m.roll_inertia_kg_m2:.1f} kg·m²" if m.roll_inertia_kg_m2 is not None else ""),
        f"tyre damping C_d {m.tyre_damping_Ns_per_m:.0f} N·s/m",
        *_interval_lines(result),
        *_constants_lines(result),
        f"objective GF {result.objective:.6g} "
        f"(certified within {100 * result.certified_gap:.3g}% of the optimum)",
    ]
    if result.gap_m is not None and not np.isfinite(result.gap_m):
        lines.append(
            "output-error gap: the identified model diverges when driven by the measured plate "
            "(unstable model; try another tyre model)"
        )
    elif result.gap_m is not None:
        lines.append(f"output-error gap {result.gap_m * 1e6:.1f} µm RMS (model driven by the measured plate)")
    if result.refined_gap_m is not None:
        lines.append(f"after DE refinement on the output error: {result.refined_gap_m * 1e6:.1f} µm RMS")
    for index, c in enumerate(result.curves):
        t = c.tanh.curve
        lines.append(
            f"\n{c.corner} damper: tanh fit c_s={t.c_s:.1f} N·s/m κ={t.kappa:.1f} N μ={t.mu:.3f} s/m "
            f"β={t.beta:.3f} (RMS {c.tanh.rms_N:.1f} N"
            + (f", outlier points {c.tanh.outliers})" if c.tanh.outliers else ")")
        )
        band = result.curve_band(index)
        if band is None:
            lines.append("  velocity m/s   force N")
            for v, f in zip(c.curve.velocity_m_s, c.curve.force_N, strict=True):
                lines.append(f"  {v:+12.4f} {f:+9.1f}")
            continue
        lines.append("  velocity m/s   force N   95% interval N")
        for v, f, low, high in zip(c.curve.velocity_m_s, c.curve.force_N, *band, strict=True):
            lines.append(f"  {v:+12.4f} {f:+9.1f}   [{low:+9.1f}, {high:+9.1f}]")
    lines.append("\ninspection figures (for comparison with today's lanes):")
    for corner, ins in result.inspection.items():
        lines.append(
            f"  {corner}: EUSAMA {ins.eusama_percent:.1f}%, minimum phase shift "
            f"{ins.phase_shift_min_deg:.1f}°, damping ratio {ins.damping_ratio:.3f}"
        )
    if result.imbalance:
        lines.append(
            f"  left/right imbalance: EUSAMA {result.imbalance['eusama_difference_points']:.1f} points, "
            f"damping {result.imbalance['damping_difference_percent']:.1f}%"
        )
    return "\n".join(lines)


def _interval_lines(result: IdentificationResult) -> list[str]:
    """The 95% intervals of the masses, tyre damping and identified stiffnesses (none without intervals)."""
    found = result.intervals_json()
    if not found:
        return []
    masses = found["masses_kg_interval"]
    assert isinstance(masses, dict)
    parts = [f"sprung mass {masses['sprung'][0]:.1f}-{masses['sprung'][1]:.1f} kg"]
    damping = found["tyre_damping_Ns_per_m_interval"]
    if isinstance(damping, list):
        parts.append(f"C_d {damping[0]:.0f}-{damping[1]:.0f} N·s/m")
    stiffness = found["stiffness_N_per_m_interval"]
    assert isinstance(stiffness, dict)
    parts += [f"{name} {low:.0f}-{high:.0f} N/m" for name, (low, high) in stiffness.items()]
    return ["95% intervals: " + ", ".join(parts)]


def _constants_lines(result: IdentificationResult) -> list[str]:
    """The vehicle constants used, each marked identified or stated."""
    v, found = result.model.vehicle, result.identified

    def origin(constant: VehicleConstant) -> str:
        return "identified" if constant in found else "stated"

    stiffness = (
        f"spring {v.spring_stiffness_N_per_m:.0f} N/m ({origin(VehicleConstant.SPRING)}), "
        f"tyre {v.tyre_stiffness_N_per_m:.0f} N/m ({origin(VehicleConstant.TYRE)})"
    )
    if v.is_axle:
        bar = f"{v.anti_roll_bar_stiffness_N_per_m:.0f} N/m ({origin(VehicleConstant.BAR)})"
        stiffness += f", anti-roll bar {bar}"
    lines = [f"stiffnesses: {stiffness}"]
    if result.model.tyre_model is TyreModel.MAXWELL:
        lines.append(
            f"tyre viscoelastic coefficient ϑ {v.tyre_viscoelastic_coefficient:.4f} at 1 ms "
            f"(relaxation time {v.maxwell_time_constant_s() * 1e3:.2f} ms, {origin(VehicleConstant.THETA)})"
        )
    guides = result.effects_json().get("effects", {})
    bands = result.intervals_json().get("effects_interval", {})
    if guides:  # a lab rig's (vehicle file: frame_guides = true)
        # imported here: `shockbench --help` imports no numpy
        from estimator.frame_guides import GUIDE_FRICTION_NAMES, GUIDED_MASSES

        each = []
        for part, key in zip(GUIDED_MASSES, GUIDE_FRICTION_NAMES, strict=True):
            band = f" (95% {bands[key][0]:.3g} to {bands[key][1]:.3g})" if key in bands else ""
            each.append(f"{part} {guides[key]:.3g} N{band}")
        lines.append(f"frame guides' friction (identified): {', '.join(each)}")
    return lines


FREE_ALL = "all"


def parse_free(text: str | None, vehicle: VehicleParameters, tyre: TyreModel) -> frozenset[VehicleConstant]:
    """`--free spring,tyre,theta,bar` or `--free all` -> the constants to identify although stated. `all`
    is every constant this model has: spring, tyre, theta (maxwell tyre), bar (axle)."""
    if not text:
        return frozenset()
    names = [name.strip() for name in text.split(",") if name.strip()]
    if FREE_ALL in names:
        every = set(VehicleConstant)
        if tyre is not TyreModel.MAXWELL:
            every.discard(VehicleConstant.THETA)
        if not vehicle.is_axle:
            every.discard(VehicleConstant.BAR)
        return frozenset(every)
    choices = ", ".join([c.value for c in VehicleConstant] + [FREE_ALL])
    free = set()
    for name in names:
        try:
            free.add(VehicleConstant(name))
        except ValueError:
            raise CliError(f"--free: unknown constant {name!r} (choose from {choices})") from None
    return frozenset(free)


def options_from_args(args: argparse.Namespace, vehicle: VehicleParameters) -> IdentifyOptions:
    from estimator.identify import IdentifyOptions, Solver, check_curve_points

    check_curve_points(args.points, "--points")
    de = DESettings(**values(args, DE_OPTIONS))
    tyre = TyreModel(args.tyre)
    return IdentifyOptions(
        tyre=tyre,
        points=args.points,
        solver=Solver(args.solver),
        de=de,
        refine_output_error=args.refine,
        free=parse_free(args.free, vehicle, tyre),
    )


def run_identify(args: argparse.Namespace) -> int:
    from estimator.identify import Solver
    from service.analysis import identify_recording

    recording, vehicle = read_recording_and_vehicle("identify", args.recording, args.vehicle)
    options = options_from_args(args, vehicle)
    progress = partial(de_progress_line, "DE") if options.solver is Solver.DE and not args.json else None
    result = identify_recording(recording, vehicle, options, progress=progress)  # the service's checks first
    for warning in result.warnings:
        print(f"shockbench identify: warning: {warning}", file=sys.stderr)
    plot = (
        Path(args.plot)
        if args.plot
        else (None if args.json else Path(args.recording).with_suffix(".curve.png"))
    )
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        print(summary(result))
    if plot is not None:
        from service.plots import save_curve_plot  # matplotlib: only when a plot is wanted

        save_curve_plot(result, plot)
        if not args.json:
            print(f"\nplot: {plot}")
    return 0


def read_points_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import numpy as np

    if not path.is_file():
        raise CliError(f"{path}: no such file")
    with path.open(newline="") as handle:
        rows = [r for r in csv.reader(line for line in handle if not line.lstrip().startswith("#")) if r]
    if not rows or [c.strip() for c in rows[0]] != ["velocity_m_s", "force_N"]:
        raise CliError(f"{path}:1: header must be velocity_m_s,force_N")
    values = []
    for line_no, row in enumerate(rows[1:], start=2):
        try:
            v, f = (float(x) for x in row)
        except ValueError:
            raise CliError(f"{path}:{line_no}: expected two numbers, got {','.join(row)!r}") from None
        if not (np.isfinite(v) and np.isfinite(f)):
            raise CliError(f"{path}:{line_no}: non-finite value")
        values.append((v, f))
    if len(values) < 5:
        raise CliError(f"{path}: {len(values)} points; the tanh fit needs at least 5")
    data = np.array(values)
    return data[:, 0], data[:, 1]


def run_demo(args: argparse.Namespace) -> int:
    """`demo` (service.cli.simulate), imported when it runs: `identify` does not pay for the simulator."""
    from service.cli.simulate import run_demo as demo

    return demo(args)


def run_fit_tanh(args: argparse.Namespace) -> int:
    from estimator.tanh_fit import fit_tanh

    velocity, force = read_points_csv(Path(args.points_csv))
    fit = fit_tanh(velocity, force)
    if args.json:
        print(json.dumps(fit.as_dict()))
    else:
        c = fit.curve
        print(
            f"f = c_s·v + κ·(tanh(μ·v + β) − tanh(β)) with c_s = {c.c_s:.4g} N·s/m, κ = {c.kappa:.4g} N, "
            f"μ = {c.mu:.4g} s/m, β = {c.beta:.4g}; RMS {fit.rms_N:.3g} N"
        )
        print("outliers (0-based rows): " + (", ".join(map(str, fit.outliers)) if fit.outliers else "none"))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "identify",
        help="identify the damper curve(s) from a recording",
        description="Identify the damper force-velocity curve, masses and tyre damping, and the "
        "stiffnesses and tyre ϑ the vehicle file does not state.",
    )
    p.add_argument("recording", help=RECORDING_HELP)
    p.add_argument("--vehicle", default=None, help=VEHICLE_HELP)
    p.add_argument("--tyre", choices=[t.value for t in TyreModel], default="maxwell")
    p.add_argument("--points", type=int, default=None, help="curve points (default 20, axle 10 per side)")
    p.add_argument("--solver", choices=SOLVERS, default="exact")
    add_options(p, DE_OPTIONS)
    p.add_argument(
        "--refine",
        action="store_true",
        help="refine the curve by DE on the output-error gap: a model that predicts the motion better "
        "(for validate), whose curve is no truer a damper curve and has no 95%% band",
    )
    p.add_argument(
        "--free",
        default=None,
        metavar="NAMES",
        help="identify these vehicle constants although the vehicle file states them: a comma list of "
        "spring, tyre, theta (maxwell tyre), bar (axle), or all (what the file omits is always identified)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--plot", default=None, help="plot file (.png or .svg); default REC.curve.png without --json"
    )
    p.set_defaults(handler=run_identify)

    p = sub.add_parser(
        "fit-tanh",
        help="fit the tanh damper model to curve points",
        description="Robust fit of eq (10) to velocity_m_s,force_N points; flags outliers.",
    )
    p.add_argument("points_csv", help="CSV with columns velocity_m_s,force_N")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=run_fit_tanh)

    p = sub.add_parser("demo", help="simulate a sweep on the embedded default bench and identify the curve")
    p.add_argument(
        "--out", default="out", help="folder for the recording, vehicle file and plot (default out)"
    )
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(handler=run_demo)
