"""Identification: from a recording and the known vehicle constants to the damper curve(s), masses, tyre
damping, inspection figures and the output-error gap.

Steps: build the affine residual system (estimator.equations), with the stiffnesses the vehicle file does
not state (or `free` asks for) as further unknowns; minimise the paper's objective GF, exactly (default,
estimator.solvers.exact) or by differential evolution (estimator.solvers.differential_evolution), in which
case the exact optimum certifies how close DE got; when ϑ is not stated (Maxwell tyre), find it first by the
bounded search over exact solves of estimator.relaxation (DE then runs at that ϑ); fit the tanh model to each
curve's points; simulate the identified model from the measured plate motion (output error); compute the
inspection figures.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import ClassVar

import numpy as np

from estimator.bandwidth import check_bandwidth
from estimator.damper import PiecewiseLinearCurve
from estimator.equations import (
    STIFFNESS_NAMES,
    TYRE_DAMPING,
    LinearResiduals,
    build,
    population_sum_of_norms,
    tyre_regressor,
)
from estimator.errors import InvalidValueError
from estimator.inspection import CornerInspection, corner_inspection, imbalance
from estimator.newton_refit import newton_refit
from estimator.output_error import IdentifiedModel, refine_on_output_error, simulate_identified
from estimator.recording import Recording
from estimator.relaxation import RELAXATION_TIME_BOUNDS_S, fit_relaxation_time
from estimator.signals import FilterChoice
from estimator.solvers.differential_evolution import DEProgress, DESettings, DifferentialEvolution
from estimator.solvers.exact import solve_exact
from estimator.tanh_fit import MIN_POINTS as MIN_TANH_POINTS
from estimator.tanh_fit import TanhFit, fit_tanh
from estimator.uncertainty import Intervals, identification_intervals
from estimator.vehicle import (
    REFERENCE_SAMPLE_TIME_S,
    TyreModel,
    VehicleConstant,
    VehicleParameters,
    relaxation_time_from_coefficient,
)

SPRUNG_FRACTION_BOUNDS = (0.5, 0.99)
"""DE search range of the sprung mass as a fraction of the mass carried by the wheel(s)."""
TYRE_DAMPING_MAX_NS_PER_M = 5000.0
STIFFNESS_BOUNDS_N_PER_M = {
    VehicleConstant.SPRING: (1e3, 3e5),
    VehicleConstant.TYRE: (3e4, 2e6),
    VehicleConstant.BAR: (0.0, 2e5),
}
"""DE search ranges of free stiffnesses: wheel rates from a motorcycle fork (14 kN/m in the paper) to a
truck; tyres from a motorcycle (101 kN/m) to a truck; anti-roll bars at the wheel."""
STARTING_RELAXATION_TIME_S = relaxation_time_from_coefficient(0.97, REFERENCE_SAMPLE_TIME_S)
"""Where the search for an unstated ϑ starts: the paper's ϑ = 0.97 at 1 ms (τ = 32 ms)."""
DAMPER_FORCE_MARGIN = 1.5
"""DE searches damper points within ± this × the largest force the body equation can ask of the damper."""


class Solver(StrEnum):
    EXACT = "exact"
    DE = "de"


class Coordinates(StrEnum):
    """Where DE searches. DECORRELATED: θ = centre + W·z with W = L⁻ᵀ, L the Cholesky factor of AᵀA (the
    equations' own normal matrix, not their solution), so the unknowns the data ties together (sprung mass
    and every curve point) become independent and the paper's low crossover rate works. RAW: the
    paper's unknowns as they are (with F = 1, CR = 0.3 DE then stalls far from the optimum; see
    BENCHMARKS.md)."""

    DECORRELATED = "decorrelated"
    RAW = "raw"


@dataclass(frozen=True)
class IdentifyOptions:
    MIN_POINTS: ClassVar[int] = MIN_TANH_POINTS
    """The fewest damper curve points accepted: the tanh fit of the curve needs as many."""
    MAX_POINTS: ClassVar[int] = 60
    """The most damper curve points accepted: more resolve nothing the 1 kHz recording carries, and the
    convex solve grows with them. The CLI, the job options and the diagnosis take their limits from here."""

    tyre: TyreModel = TyreModel.MAXWELL
    points: int | None = None
    """Damper curve points; default 20 for a quarter car, 10 per side for an axle."""
    solver: Solver = Solver.EXACT
    nsample: int | None = 5000
    de: DESettings = field(default_factory=DESettings)
    de_coordinates: Coordinates = Coordinates.DECORRELATED
    output_error: bool = True
    refine_output_error: bool = False
    free: frozenset[VehicleConstant] = frozenset()
    """Constants to identify although the vehicle file states them (those it does not state always are)."""
    intervals: bool = True
    """95% confidence intervals (estimator.uncertainty): one more convex solve on a refined grid."""

    def __post_init__(self) -> None:
        check_curve_points(self.points)


def check_curve_points(points: int | None, field: str = "points") -> None:
    """InvalidValueError (naming `field`) unless `points` is None or within IdentifyOptions' limits."""
    low, high = IdentifyOptions.MIN_POINTS, IdentifyOptions.MAX_POINTS
    if points is not None and not low <= points <= high:
        raise InvalidValueError(
            f"{field} must lie between {low} (the tanh fit needs as many) and {high}, got {points}",
            field=field,
        )


@dataclass(frozen=True)
class CornerCurve:
    corner: str  # "single", "left" or "right"
    curve: PiecewiseLinearCurve
    tanh: TanhFit


@dataclass
class IdentificationResult:
    model: IdentifiedModel
    curves: list[CornerCurve]
    objective: float
    solver: Solver
    certified_gap: float
    """Relative optimality gap of the reported solution, certified by the exact solver's dual bound."""
    gap_m: float | None
    inspection: dict[str, CornerInspection]
    imbalance: dict[str, float] | None
    system: LinearResiduals
    de_generations: int | None = None
    refined_gap_m: float | None = None
    identified: frozenset[VehicleConstant] = frozenset()
    """The vehicle constants found from the recording (the rest are the vehicle file's)."""
    warnings: list[str] = field(default_factory=list)
    intervals: Intervals | None = None
    """95% confidence intervals of θ (estimator.uncertainty), None when not asked for."""

    def curve_band(self, index: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(low, high) force at the grid points of curve `index`, None without intervals."""
        if self.intervals is None:
            return None
        where = self.system.curve_slices[index]
        return self.intervals.low[where], self.intervals.high[where]

    def intervals_json(self) -> dict[str, object]:
        """The `*_interval` keys of the JSON ([low, high] pairs), empty without intervals. The unsprung
        mass is M − M_s (axle: (M − M_s)/2), so its interval is the sprung one's mirrored."""
        if self.intervals is None:
            return {}
        sprung = self.intervals.interval("sprung_mass_kg")
        assert sprung is not None
        vehicle = self.model.vehicle
        unsprung = [vehicle.unsprung_mass_kg(sprung[1]), vehicle.unsprung_mass_kg(sprung[0])]
        out: dict[str, object] = {
            "masses_kg_interval": {"sprung": list(sprung), "unsprung": unsprung},
            "stiffness_N_per_m_interval": {
                key: list(interval)
                for key, name in STIFFNESS_JSON_KEYS.items()
                if (interval := self.intervals.interval(name)) is not None
            },
        }
        damping = self.intervals.interval(TYRE_DAMPING)
        out["tyre_damping_Ns_per_m_interval"] = list(damping) if damping is not None else None
        inertia = self.intervals.interval("roll_inertia_kg_m2")
        if inertia is not None:
            out["roll_inertia_kg_m2_interval"] = list(inertia)
        return out

    def to_json(self) -> dict[str, object]:
        """The stable JSON shape of `shockbench identify --json`."""
        m = self.model
        inspection: dict[str, object]
        if len(self.inspection) == 1:
            inspection = self.inspection["single"].as_dict()
        else:
            inspection = {side: ins.as_dict() for side, ins in self.inspection.items()}
            inspection["imbalance"] = self.imbalance
        curves: list[dict[str, object]] = []
        for index, c in enumerate(self.curves):
            entry: dict[str, object] = {
                "corner": c.corner,
                "velocity_m_s": c.curve.velocity_m_s.tolist(),
                "force_N": c.curve.force_N.tolist(),
            }
            band = self.curve_band(index)
            if band is not None:
                entry["force_N_low"], entry["force_N_high"] = band[0].tolist(), band[1].tolist()
            entry |= {"tanh": c.tanh.curve.as_dict(), "tanh_rms_N": c.tanh.rms_N, "outliers": c.tanh.outliers}
            curves.append(entry)
        out: dict[str, object] = {
            "curves": curves,
            "masses_kg": {"sprung": m.sprung_mass_kg, "unsprung": m.unsprung_mass_kg},
            "stiffness_N_per_m": self.stiffness_json(),
            "tyre_viscoelastic_coefficient": m.vehicle.tyre_viscoelastic_coefficient,
            "tyre_relaxation_time_s": m.vehicle.tyre_relaxation_time_s,
            "tyre_viscoelastic_identified": VehicleConstant.THETA in self.identified,
            "tyre_damping_Ns_per_m": m.tyre_damping_Ns_per_m,
            "tyre_model": m.tyre_model.value,
            "objective": self.objective,
            "solver": self.solver.value,
            "certified_gap": self.certified_gap,
            "gap_m": self.gap_m if self.gap_m is None or np.isfinite(self.gap_m) else None,
            "gap_diverged": self.gap_m is not None and not np.isfinite(self.gap_m),
            "inspection": inspection,
            "filters": {
                "kinematics_cutoff_Hz": self.system.filters.kinematics_cutoff_Hz,
                "equation_cutoff_Hz": self.system.filters.equation_cutoff_Hz,
                "noise_floor_m": self.system.filters.noise_floor_m,
            },
        }
        if m.roll_inertia_kg_m2 is not None:
            out["roll_inertia_kg_m2"] = m.roll_inertia_kg_m2
        if m.vehicle.is_axle:
            out["track_m"] = m.vehicle.track_m  # what `validate` needs to rebuild the axle's roll
        if self.refined_gap_m is not None:
            out["refined_gap_m"] = self.refined_gap_m
        out |= self.intervals_json()
        out["warnings"] = list(self.warnings)
        return out

    def stiffness_json(self) -> dict[str, object]:
        """{spring, tyre, (anti_roll_bar,) identified: [names]} in N/m; ϑ is reported beside it."""
        v = self.model.vehicle
        out: dict[str, object] = {"spring": v.spring_stiffness_N_per_m, "tyre": v.tyre_stiffness_N_per_m}
        if v.is_axle:
            out["anti_roll_bar"] = v.anti_roll_bar_stiffness_N_per_m
        found = self.identified & set(STIFFNESS_NAMES)
        out["identified"] = [c.value for c in VehicleConstant if c in found]
        return out


STIFFNESS_JSON_KEYS = {
    "spring": "spring_stiffness_N_per_m",
    "tyre": "tyre_stiffness_N_per_m",
    "anti_roll_bar": "anti_roll_bar_stiffness_N_per_m",
}
"""The stiffness_N_per_m(_interval) key of each stiffness unknown."""


def de_bounds(system: LinearResiduals, vehicle: VehicleParameters) -> np.ndarray:
    """Physical search box, by unknown: sprung mass fraction, roll inertia, tyre damping, damper forces,
    free stiffnesses."""
    mass = vehicle.mass_kg
    stiffness_of = {name: constant for constant, name in STIFFNESS_NAMES.items()}
    body_equation = 2 if vehicle.is_axle else 0  # heave, or the quarter car's body
    # the body equation bounds what the dampers can be asked for: |F_d| <~ M·|ẍ_s| + |spring and bar|
    body = np.abs(system.matrix[body_equation, :, 0]) * mass + np.abs(system.offset[body_equation])
    for index, name in enumerate(system.parameter_names):
        if name in stiffness_of:
            upper = STIFFNESS_BOUNDS_N_PER_M[stiffness_of[name]][1]
            body = body + upper * np.abs(system.matrix[body_equation, :, index])
    force_limit = DAMPER_FORCE_MARGIN * float(np.max(body))
    bounds: list[tuple[float, float]] = []
    for name in system.parameter_names:
        if name == "sprung_mass_kg":
            bounds.append((SPRUNG_FRACTION_BOUNDS[0] * mass, SPRUNG_FRACTION_BOUNDS[1] * mass))
        elif name == "roll_inertia_kg_m2":
            bounds.append((0.0, mass * float(vehicle.track_m) ** 2 / 2.0))
        elif name == TYRE_DAMPING:
            bounds.append((0.0, TYRE_DAMPING_MAX_NS_PER_M))
        elif name in stiffness_of:
            bounds.append(STIFFNESS_BOUNDS_N_PER_M[stiffness_of[name]])
        else:
            bounds.append((-force_limit, force_limit))
    return np.array(bounds)


@dataclass(frozen=True)
class DEProblem:
    """The paper's objective as DE sees it: search box and the map from search coordinates to θ."""

    system: LinearResiduals
    transform: np.ndarray
    centre: np.ndarray
    bounds: np.ndarray

    def theta(self, z: np.ndarray) -> np.ndarray:
        return self.centre + z @ self.transform.T

    def objective(self, z: np.ndarray) -> np.ndarray:
        """GF in float64 for one point (p,) or a population (P, p) of search coordinates."""
        return self.system.objective(self.theta(z))

    def population_objective32(self) -> Callable[[np.ndarray], np.ndarray]:
        """GF of a whole population in float32 (half the memory traffic; DE only ranks with it)."""
        flat = np.ascontiguousarray(self.system.matrix.reshape(-1, self.system.n_params).T)
        equations = self.system.matrix.shape[0]
        flat32 = (self.transform.T @ flat).astype(np.float32)
        offset32 = (self.system.offset.reshape(-1) + self.centre @ flat).astype(np.float32)

        def objective(z: np.ndarray) -> np.ndarray:
            return population_sum_of_norms(z.astype(np.float32), flat32, offset32, equations)

        return objective


def de_problem(system: LinearResiduals, vehicle: VehicleParameters, coordinates: Coordinates) -> DEProblem:
    bounds = de_bounds(system, vehicle)
    if coordinates is Coordinates.RAW:
        return DEProblem(system, np.eye(system.n_params), np.zeros(system.n_params), bounds)
    flat = system.matrix.reshape(-1, system.n_params)
    chol = np.linalg.cholesky(flat.T @ flat)
    half = np.abs(chol.T) @ ((bounds[:, 1] - bounds[:, 0]) / 2.0)  # the θ box seen in z, enclosed
    return DEProblem(system, np.linalg.inv(chol.T), bounds.mean(axis=1), np.column_stack([-half, half]))


def run_de(
    system: LinearResiduals,
    vehicle: VehicleParameters,
    options: IdentifyOptions,
    progress: Callable[[DEProgress], bool | None] | None = None,
    cancel: threading.Event | None = None,
) -> tuple[np.ndarray, int, bool]:
    """DE on the paper's objective; returns θ, generations run, and whether it was cancelled."""
    problem = de_problem(system, vehicle, options.de_coordinates)
    solver = DifferentialEvolution(
        problem.population_objective32(), problem.bounds, options.de, progress, cancel
    )
    result = solver.solve()
    return problem.theta(result.theta), result.generations, result.cancelled


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
    options: IdentifyOptions = IdentifyOptions(),
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
    model = IdentifiedModel(
        vehicle=resolved,
        tyre_model=options.tyre,
        curves=curves,
        sprung_mass_kg=float(theta[0]),
        tyre_damping_Ns_per_m=system.value(theta, TYRE_DAMPING) or 0.0,
        roll_inertia_kg_m2=float(theta[1]) if vehicle.is_axle else None,
    )
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
