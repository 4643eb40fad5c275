"""Identification: from a recording and the known vehicle constants to the damper curve(s), masses, tyre
damping, inspection figures and the output-error gap.

Steps: build the affine residual system (estimator.equations), with the stiffnesses the vehicle file does
not state (or `free` asks for) as further unknowns; minimise the paper's objective GF, exactly (default,
estimator.solvers.exact) or by differential evolution (estimator.solvers.differential_evolution), in which
case the exact optimum certifies how close DE got; when ϑ is not stated (Maxwell tyre), find it first by the
bounded search over exact solves of estimator.relaxation (DE then runs at that ϑ); fit the tanh model to each
curve's points; simulate the identified model from the measured plate motion (output error); compute the
inspection figures.

The options are declared in estimator.identify_options, the result in estimator.identification_result and
the DE search in estimator.de_search; their public names are importable from here as well.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import fields, replace

import numpy as np

from estimator.bandwidth import check_bandwidth
from estimator.damper import PiecewiseLinearCurve
from estimator.de_search import (
    DAMPER_FORCE_MARGIN,
    SPRUNG_FRACTION_BOUNDS,
    STIFFNESS_BOUNDS_N_PER_M,
    TYRE_DAMPING_MAX_NS_PER_M,
    DEProblem,
    de_bounds,
    de_problem,
    run_de,
)
from estimator.equations import STIFFNESS_NAMES, TYRE_DAMPING, LinearResiduals, build, tyre_regressor
from estimator.errors import InvalidValueError
from estimator.frame_guides import GUIDE_FRICTION_NAMES, GUIDED_MASSES
from estimator.identification_result import STIFFNESS_JSON_KEYS, CornerCurve, IdentificationResult
from estimator.identify_options import Coordinates, IdentifyOptions, Solver, check_curve_points
from estimator.inspection import CornerInspection, corner_inspection, imbalance
from estimator.model_io import ModelEffects, ModelWithEffects
from estimator.newton_refit import newton_refit
from estimator.output_error import IdentifiedModel, refine_on_output_error, simulate_identified
from estimator.recording import Recording
from estimator.relaxation import RELAXATION_TIME_BOUNDS_S, fit_relaxation_time
from estimator.signals import FilterChoice
from estimator.solvers.differential_evolution import DEProgress
from estimator.solvers.exact import solve_exact
from estimator.tanh_fit import fit_tanh
from estimator.uncertainty import identification_intervals
from estimator.vehicle import (
    REFERENCE_SAMPLE_TIME_S,
    TyreModel,
    VehicleConstant,
    VehicleParameters,
    relaxation_time_from_coefficient,
)

__all__ = [  # the identification's public names, wherever their module (options, result, DE search)
    "DAMPER_FORCE_MARGIN",
    "SPRUNG_FRACTION_BOUNDS",
    "STARTING_RELAXATION_TIME_S",
    "STIFFNESS_BOUNDS_N_PER_M",
    "STIFFNESS_JSON_KEYS",
    "TYRE_DAMPING_MAX_NS_PER_M",
    "Coordinates",
    "CornerCurve",
    "DEProblem",
    "IdentificationResult",
    "IdentifyOptions",
    "Solver",
    "check_curve_points",
    "constants_to_identify",
    "de_bounds",
    "de_problem",
    "identify",
    "run_de",
]

STARTING_RELAXATION_TIME_S = relaxation_time_from_coefficient(0.97, REFERENCE_SAMPLE_TIME_S)
"""Where the search for an unstated ϑ starts: the paper's ϑ = 0.97 at 1 ms (τ = 32 ms)."""
DEFAULT_OPTIONS = IdentifyOptions()


def _inspection(
    model: IdentifiedModel, recording: Recording, system: LinearResiduals
) -> tuple[dict[str, CornerInspection], dict[str, float] | None]:
    v = model.vehicle
    dt = recording.sample_time_s
    kin = system.kinematics
    theta = v.viscoelastic_coefficient_at(dt) if model.tyre_model is TyreModel.MAXWELL else None
    sides = [("single", "")] if not v.is_axle else [("left", "_l"), ("right", "_r")]
    sprung_per_corner = model.sprung_mass_kg / len(sides)
    result: dict[str, CornerInspection] = {}
    for (corner, suffix), curve, velocity in zip(sides, model.curves, system.velocity_m_s, strict=True):
        t, r = kin[f"x_t{suffix}"], kin[f"x_r{suffix}"]
        g = tyre_regressor(t.velocity_m_s - r.velocity_m_s, model.tyre_model, theta)
        viscous = model.tyre_damping_Ns_per_m * g if g is not None else 0.0
        dynamic = -float(v.tyre_stiffness_N_per_m) * (t.position_m - r.position_m) - viscous
        keep = system.sample_index[0], system.sample_index[-1] + 1  # leave out filter start-up transients
        result[corner] = corner_inspection(
            static_load_N=v.static_wheel_load_N,
            dynamic_force_N=dynamic[keep[0] : keep[1]],
            plate_m=r.position_m[keep[0] : keep[1]],
            sample_time_s=dt,
            damper_force_N=curve.force(velocity),
            velocity_m_s=velocity,
            spring_stiffness_N_per_m=float(v.spring_stiffness_N_per_m),
            sprung_mass_kg=sprung_per_corner,
        )
    balance = imbalance(result["left"], result["right"]) if v.is_axle else None
    return result, balance


def constants_to_identify(vehicle: VehicleParameters, options: IdentifyOptions) -> frozenset[VehicleConstant]:
    """What the recording has to give: the constants the vehicle does not state and those `free` asks for.
    ϑ only with the Maxwell tyre (the other tyre models have no ϑ); the bar only on an axle."""
    wanted = vehicle.unknown | options.free
    if VehicleConstant.BAR in wanted and not vehicle.is_axle:
        raise InvalidValueError("the anti-roll bar ('bar') applies to an axle only")
    if options.tyre is not TyreModel.MAXWELL:
        if VehicleConstant.THETA in options.free:
            raise InvalidValueError("ϑ ('theta') belongs to the maxwell tyre model only")
        wanted = wanted - {VehicleConstant.THETA}
    return frozenset(wanted)


def _resolved(
    vehicle: VehicleParameters, system: LinearResiduals, theta: np.ndarray, relaxation_time_s: float | None
) -> VehicleParameters:
    """The vehicle with every identified constant filled in (what the output error and inspection use)."""
    changes: dict[str, float] = {}
    for name in STIFFNESS_NAMES.values():
        value = system.value(theta, name)
        if value is not None:
            if not value > 0:
                raise InvalidValueError(
                    f"the identified {name} is {value:.4g}, not positive: the recording does not "
                    "determine it (state it in the vehicle file)"
                )
            changes[name] = value
    resolved = replace(vehicle, **changes)
    return resolved.with_relaxation_time(relaxation_time_s) if relaxation_time_s is not None else resolved


def _with_frame_guides(model: IdentifiedModel, system: LinearResiduals, theta: np.ndarray) -> IdentifiedModel:
    """The model with a rig's frame guides' frictions as found (estimator.frame_guides), held as the model
    file's effects so that its physics, its JSON and `validate` carry them; the model as it is where the
    system has no guides (every vehicle on a plate)."""
    frictions = {name: system.value(theta, name) for name in GUIDE_FRICTION_NAMES}
    if None in frictions.values():
        return model
    same = {f.name: getattr(model, f.name) for f in fields(model)}
    return ModelWithEffects(**same, effects=ModelEffects(**frictions))


def _guide_warnings(model: IdentifiedModel) -> list[str]:
    """A frame guide's friction fitted below zero would feed energy in: say so, with what it means."""
    effects = model.effects if isinstance(model, ModelWithEffects) else ModelEffects()
    frictions = (getattr(effects, name) for name in GUIDE_FRICTION_NAMES)
    below = [(mass, value) for mass, value in zip(GUIDED_MASSES, frictions, strict=True) if value < 0]
    return [
        f"the frame guides' {mass} friction came out below zero ({value:.3g} N): a friction "
        "cannot feed energy in; the recording does not determine it, or a force the model lacks acts there"
        for mass, value in below
    ]


def _edge_warning(relaxation_time_s: float) -> list[str]:
    low, high = RELAXATION_TIME_BOUNDS_S
    if relaxation_time_s < low * 1.02 or relaxation_time_s > high / 1.02:
        return [
            f"the tyre's relaxation time came out at the edge of its search range ({low * 1e3:g}-"
            f"{high * 1e3:g} ms): {relaxation_time_s * 1e3:.3g} ms; this recording does not determine ϑ well"
        ]
    return []


def identify(
    recording: Recording,
    vehicle: VehicleParameters,
    options: IdentifyOptions = DEFAULT_OPTIONS,
    progress: Callable[[DEProgress], bool | None] | None = None,
    cancel: threading.Event | None = None,
) -> IdentificationResult:
    """Identify the damper curve(s), the masses, the tyre damping and the vehicle constants the file does not
    state (or options.free names) from a recording. An undersampled recording is refused here
    (InsufficientBandwidthError, estimator.bandwidth), so every path (CLI, job, library) gets the check;
    a marginal one is identified with the bandwidth warning among the result's warnings."""
    if vehicle.is_axle != recording.is_axle:
        kind = "axle" if vehicle.is_axle else "quarter-car"
        raise InvalidValueError(
            f"the vehicle file is for a {kind} model but the recording's channels are not"
        )
    bandwidth = check_bandwidth(recording)
    unknown = constants_to_identify(vehicle, options)
    search_theta = VehicleConstant.THETA in unknown
    start = vehicle
    if options.tyre is TyreModel.MAXWELL and vehicle.tyre_viscoelastic_coefficient is None:
        start = vehicle.with_relaxation_time(STARTING_RELAXATION_TIME_S)
    system = build(recording, start, options.tyre, options.points, options.nsample, free=unknown)
    relaxation_time = None
    warnings: list[str] = list(bandwidth.warnings)
    if search_theta:
        fit = fit_relaxation_time(system)
        system, exact, relaxation_time = fit.system, fit.solution, fit.relaxation_time_s
        warnings += _edge_warning(relaxation_time)
    else:
        exact = solve_exact(system)
    generations = None
    if options.solver is Solver.DE:
        theta, generations, cancelled = run_de(system, start, options, progress, cancel)
        if cancelled:
            raise InterruptedError("identification cancelled")
    else:
        theta = exact.theta
    objective = float(system.objective(theta))
    certified_gap = (objective - exact.lower_bound) / objective if objective > 0 else 0.0
    curves = tuple(
        PiecewiseLinearCurve(g, theta[s]) for g, s in zip(system.grids_m_s, system.curve_slices, strict=True)
    )
    resolved = _resolved(start, system, theta, relaxation_time)
    intervals = None
    if options.intervals:

        def rebuild(grids: list[np.ndarray], filters: FilterChoice) -> LinearResiduals:
            return build(recording, resolved, options.tyre, None, options.nsample, filters, grids, unknown)

        def refit(other: LinearResiduals, near: np.ndarray) -> np.ndarray:
            bounds = RELAXATION_TIME_BOUNDS_S if search_theta else None
            return newton_refit(other, near, relaxation_time_bounds_s=bounds).theta

        intervals = identification_intervals(
            system, theta, recording.sample_time_s, search_theta, rebuild, refit
        )
    model = _with_frame_guides(
        IdentifiedModel(
            vehicle=resolved,
            tyre_model=options.tyre,
            curves=curves,
            sprung_mass_kg=float(theta[0]),
            tyre_damping_Ns_per_m=system.value(theta, TYRE_DAMPING) or 0.0,
            roll_inertia_kg_m2=float(theta[1]) if vehicle.is_axle else None,
        ),
        system,
        theta,
    )
    warnings += _guide_warnings(model)
    noise_m = system.filters.noise_floor_m
    gap = (
        simulate_identified(model, recording, system.kinematics, noise_m).gap_m
        if options.output_error
        else None
    )
    refined_gap = None
    if options.refine_output_error:
        model, refined_gap = refine_on_output_error(
            model, recording, system.kinematics, noise_m, cancel=cancel
        )
        warnings.append(
            "refined on the output error: the model predicts the motion better, but its damper curve is no "
            "truer a damper curve (it takes up more of what the model lacks; identify without refining for "
            "the damper)"
            + ("; the curve and the tyre damping have no 95% band (the equation fit's bands, which the "
               "refinement moves off)" if intervals is not None else "")
        )  # fmt: skip
    inspection, balance = _inspection(model, recording, system)
    corners = ["single"] if not vehicle.is_axle else ["left", "right"]
    fitted = [
        CornerCurve(c, curve, fit_tanh(curve.velocity_m_s, curve.force_N))
        for c, curve in zip(corners, model.curves, strict=True)
    ]
    return IdentificationResult(
        model,
        fitted,
        objective,
        options.solver,
        certified_gap,
        gap,
        inspection,
        balance,
        system,
        generations,
        refined_gap,
        unknown,
        warnings,
        intervals,
    )


def identify_unstated(
    recording: Recording,
    vehicle: VehicleParameters,
    also_free: frozenset[VehicleConstant],
    points: int | None = None,
) -> VehicleParameters:
    """The vehicle with the constants its file does not state identified from the recording, those of
    `also_free` it states identified beside them and then put back as stated. The model doctor starts so:
    an identified ϑ must not absorb a wrong stated rate that it will test (a Maxwell element relaxing more
    slowly than the sweep's periods acts as a spring). Where the recording does not determine `also_free`
    (one comes out not positive), they are held as stated throughout. A rig's frame guides are left out of
    this fit, as out of the doctor's starting model, which tests them as a family: its ϑ is fitted in the
    form the doctor starts from (fitted with the guides, it changed the doctor's path on DEV lab rigs for no
    gain: docs/doctor-v2-notes.md)."""
    options = IdentifyOptions(points=points, output_error=False, intervals=False)
    unguided, guides = replace(vehicle, frame_guides=False), {"frame_guides": vehicle.frame_guides}
    try:
        found = identify(recording, unguided, replace(options, free=also_free)).model.vehicle
    except InvalidValueError:
        return replace(identify(recording, unguided, options).model.vehicle, **guides)
    stated = {STIFFNESS_NAMES[c]: getattr(vehicle, STIFFNESS_NAMES[c]) for c in also_free - vehicle.unknown}
    return replace(found, **stated, **guides)
