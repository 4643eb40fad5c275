"""A model with effect families added, and how it is fitted.

ModelStructure says which families a model has beyond the vehicle file's constants (the starting tyre model
counts: kelvin-voigt starts with tyre_damping, maxwell with tyre_viscoelastic). fit() identifies it:

1. the recording is corrected for the model's channel families (estimator.laser_channels);
2. the paper's equations are built on it (estimator.equations, with the damper grid and filters of the
   uncorrected recording, so every candidate shares its unknowns; the grid has knots at 0, ±5 and ±10 mm/s,
   low_speed_grids, so that the curve follows a damper's low-speed rise and a friction step is only what
   the curve cannot make) and each force family appends its columns (estimator.doctor.catalog);
3. the paper's objective is minimised exactly (estimator.solvers.exact). Channel parameters are found by
   Gauss-Newton steps: the residual's change per unit of each parameter is taken by finite differences at
   the current solution (channel_jacobian), appended as columns, solved jointly, repeated. With
   tyre_liftoff the airborne samples come from the fitted tyre force and are re-determined once.

Speed: a diagnosis fits many models of one recording, most on the same corrected recording, so the
equations built on it and the families' columns are kept per Reference (a small least-recently-used cache).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from estimator.damper import PiecewiseLinearCurve
from estimator.doctor.catalog import (
    CATALOG,
    CHANNEL_PARAMETERS,
    MAX_DELAY_S,
    SPRING_RATE_UNKNOWN,
    TYRE_RATE_UNKNOWN,
    EffectInstance,
    EffectName,
    hinge_knots_m,
    hinge_unknowns,
    stribeck_velocity_m_s,
)
from estimator.doctor.columns import EquationSignals, restrict, with_columns
from estimator.equations import LinearResiduals, build
from estimator.errors import InvalidValueError
from estimator.laser_channels import ChannelCorrections
from estimator.recording import Recording
from estimator.signals import FilterChoice
from estimator.solvers.exact import solve_exact
from estimator.vehicle import TyreModel, VehicleConstant, VehicleParameters

__all__ = ["ChannelCorrections", "FitSettings", "FittedModel", "ModelStructure", "Reference", "fit"]

GAUSS_NEWTON_ITERATIONS = 4
HALVINGS = 3
"""A Gauss-Newton step that raises the objective is halved at most this many times."""
GAUSS_NEWTON_STEP = {"delay": 5e-4, "lag": 5e-4, "average": 1e-3, "gain": 1e-3, "offset": 1e-4}
"""Finite-difference step of each kind of channel parameter (s, s, s, relative, m)."""
GAUSS_NEWTON_TOLERANCE = {"delay": 2e-6, "lag": 2e-6, "average": 4e-6, "gain": 1e-5, "offset": 1e-7}
NONNEGATIVE = frozenset({"delay", "lag", "average"})
"""Channel parameters that cannot be negative (a sensor lags, it does not lead), kept in [0, MAX_DELAY_S]."""


@dataclass(frozen=True)
class ModelStructure:
    """The families a model has beyond the vehicle file's constants, in the order they were added."""

    effects: tuple[EffectInstance, ...] = ()

    def with_effect(self, effect: EffectInstance) -> ModelStructure:
        return replace(self, effects=(*self.effects, effect))

    def has(self, name: EffectName) -> bool:
        return any(e.name is name for e in self.effects)

    @property
    def channel_parameters(self) -> list[tuple[EffectInstance, str]]:
        """(family, kind) of every Gauss-Newton parameter, in order."""
        return [
            (e, kind)
            for e in self.effects
            if CATALOG[e.name].channel_kind is not None
            for kind in CHANNEL_PARAMETERS[
                (e.name, e.variant if e.name is EffectName.SENSOR_DYNAMICS else None)
            ]
        ]

    @property
    def labels(self) -> list[str]:
        return [e.label for e in self.effects]


def starting_structure(tyre: TyreModel) -> ModelStructure:
    """The structure a `--tyre` option stands for."""
    if tyre is TyreModel.KELVIN_VOIGT:
        return ModelStructure((EffectInstance(EffectName.TYRE_DAMPING),))
    if tyre is TyreModel.MAXWELL:
        return ModelStructure((EffectInstance(EffectName.TYRE_VISCOELASTIC),))
    return ModelStructure()


def corrections_of(parameters: list[tuple[EffectInstance, str]], values: np.ndarray) -> ChannelCorrections:
    """The channel corrections that Gauss-Newton parameters (family, kind) with these values stand for."""
    tables: dict[str, dict[str, float]] = {k: {} for k in ("delay", "lag", "average", "gain", "offset")}
    for (effect, kind), value in zip(parameters, values, strict=True):
        tables[kind][str(effect.channel)] = float(value)
    return ChannelCorrections(
        tables["delay"], tables["offset"], tables["lag"], tables["average"], tables["gain"]
    )


@dataclass(frozen=True)
class FitSettings:
    points: int | None = None
    """Damper curve points (default 20 for a quarter car, 10 per side for an axle), before low-speed knots."""
    nsample: int | None = 5000


@dataclass
class FittedModel:
    """A structure identified on a recording: θ of the extended system (built on the corrected recording)."""

    structure: ModelStructure
    vehicle: VehicleParameters
    theta: np.ndarray
    system: LinearResiduals
    """The extended system on all selected samples (also when the fit used only some of them)."""
    signals: EquationSignals
    channel_values: np.ndarray
    """The Gauss-Newton parameters, in structure.channel_parameters' order."""
    airborne: list[np.ndarray]
    """Per corner, where the fitted tyre force would pull on the plate (only with tyre_liftoff)."""
    objective: float
    knots_m: tuple[float, ...]
    """spring_curve's hinge knots on this recording (catalog.hinge_knots_m)."""
    curve_override: tuple[PiecewiseLinearCurve, ...] | None = None
    """Damper curves to simulate instead of the fitted points (a bootstrap truth's smooth curves)."""

    def value(self, name: str, default: float = 0.0) -> float:
        names = self.system.parameter_names
        return float(self.theta[names.index(name)]) if name in names else default

    @property
    def sprung_mass_kg(self) -> float:
        return float(self.theta[0])

    @property
    def roll_inertia_kg_m2(self) -> float | None:
        return float(self.theta[1]) if self.vehicle.is_axle else None

    @property
    def curves(self) -> tuple[PiecewiseLinearCurve, ...]:
        if self.curve_override is not None:
            return self.curve_override
        return tuple(
            PiecewiseLinearCurve(g, self.theta[s])
            for g, s in zip(self.system.grids_m_s, self.system.curve_slices, strict=True)
        )

    @property
    def maxwell_damping_Ns_per_m(self) -> float:
        """C_d of the Maxwell element (0 without one)."""
        return self.value("maxwell_damping_Ns_per_m")

    @property
    def corrections(self) -> ChannelCorrections:
        return corrections_of(self.structure.channel_parameters, self.channel_values)

    def channel_value(self, effect: EffectInstance, kind: str) -> float:
        for (e, k), value in zip(self.structure.channel_parameters, self.channel_values, strict=True):
            if e == effect and k == kind:
                return float(value)
        return 0.0

    def residuals(self) -> np.ndarray:
        """(equations, selected samples) residual forces, N."""
        return self.system.residuals(self.theta)

    @property
    def spring_stiffness_N_per_m(self) -> float:
        """K_s at the static position: the stated rate plus spring_curve's rate change (if it has one)."""
        return float(self.vehicle.spring_stiffness_N_per_m or 0.0) + self.value(SPRING_RATE_UNKNOWN)

    @property
    def tyre_stiffness_N_per_m(self) -> float:
        """K_t as this model has it: the stated rate plus its fitted correction (if it has one)."""
        return float(self.vehicle.tyre_stiffness_N_per_m or 0.0) + self.value(TYRE_RATE_UNKNOWN)

    @property
    def hinge_rates_N_per_m(self) -> np.ndarray:
        """spring_curve's hinge rates, one per knot (zeros without the family)."""
        return np.array([self.value(n) for n in hinge_unknowns(self.knots_m)])

    @property
    def stribeck_velocity_m_s(self) -> float:
        """v_s of the model's low_speed_friction variant (0 without the family)."""
        friction = [e for e in self.structure.effects if e.name is EffectName.LOW_SPEED_FRICTION]
        return stribeck_velocity_m_s(friction[0]) if friction else 0.0

    @property
    def airborne_fraction(self) -> float:
        return float(np.mean([a.mean() for a in self.airborne])) if self.airborne else 0.0


BUILD_CACHE_ENTRIES = 8
"""Equation systems a Reference keeps (the most recently used)."""
COLUMN_CACHE_ENTRIES = 32
"""Family columns a Reference keeps (the most recently used)."""


@dataclass(frozen=True)
class Reference:
    """What every fit of one recording shares: the damper grid(s) and filters of the uncorrected recording,
    the spring hinges' knots, the constants identified from it, and the systems built on it so far."""

    recording: Recording
    vehicle: VehicleParameters
    settings: FitSettings
    grids: list[np.ndarray]
    filters: FilterChoice
    knots_m: tuple[float, ...]
    identified: frozenset[VehicleConstant] = frozenset()
    built: dict[tuple, tuple[LinearResiduals, EquationSignals]] = field(
        default_factory=dict, compare=False, repr=False
    )
    columns: dict[tuple, tuple[dict[str, np.ndarray], np.ndarray | None]] = field(
        default_factory=dict, compare=False, repr=False
    )
    lock: threading.Lock = field(default_factory=threading.Lock, compare=False, repr=False)
    """Guards the caches: candidates are fitted in parallel threads."""

    @staticmethod
    def of(
        recording: Recording,
        vehicle: VehicleParameters,
        settings: FitSettings,
        identified: frozenset[VehicleConstant] = frozenset(),
    ) -> Reference:
        if vehicle.is_axle != recording.is_axle:
            kind = "axle" if vehicle.is_axle else "quarter-car"
            raise InvalidValueError(
                f"the vehicle file is for a {kind} model but the recording's channels are not"
            )
        base = build(recording, vehicle, TyreModel.SPRING, settings.points, settings.nsample)
        knots = hinge_knots_m(recording, vehicle)
        return Reference(
            recording, vehicle, settings, low_speed_grids(base.grids_m_s), base.filters, knots, identified
        )


LOW_SPEED_KNOTS_M_S = (0.0, 0.01)
"""Suspension velocities (m/s) at which a grid with low-speed knots gets a knot (at ± each)."""
LOW_SPEED_CLEARANCE = 0.5
"""A uniform knot closer to a low-speed knot than this share of the low-speed knots' spacing gives way."""


def low_speed_grids(grids: list[np.ndarray]) -> list[np.ndarray]:
    """The grids with knots at ±LOW_SPEED_KNOTS_M_S added (those inside the grid), the uniform knots too close
    to them dropped (not the end knots). An axle's two grids keep the same number of knots (the widest
    intervals of the shorter one are halved)."""
    extra = np.unique(np.concatenate([-np.asarray(LOW_SPEED_KNOTS_M_S), LOW_SPEED_KNOTS_M_S]))
    clearance = LOW_SPEED_CLEARANCE * float(np.min(np.diff(extra)))
    changed = []
    for grid in grids:
        inside = extra[(extra > grid[0]) & (extra < grid[-1])]
        distance = np.min(np.abs(grid[:, None] - inside[None, :]), axis=1, initial=np.inf)
        ends = (grid == grid[0]) | (grid == grid[-1])
        changed.append(np.unique(np.concatenate([grid[(distance >= clearance) | ends], inside])))
    return _same_size(changed)


def _same_size(grids: list[np.ndarray]) -> list[np.ndarray]:
    """The grids with the widest intervals of the shorter ones halved until all have as many knots (an axle's
    two curves must)."""
    size = max(g.size for g in grids)
    changed = []
    for grid in grids:
        while grid.size < size:
            widths = np.diff(grid)
            widest = int(np.argmax(widths))
            grid = np.insert(grid, widest + 1, 0.5 * (grid[widest] + grid[widest + 1]))
        changed.append(grid)
    return changed


def _airborne(
    signals: EquationSignals, dashpot: float, maxwell: float, stiffness_change: float
) -> list[np.ndarray]:
    """Per corner, 1.0 where the tyre force of the fitted tyre (its rate corrected by stiffness_change)
    would pull on the plate, else 0.0. The Maxwell element is not driven while the tyre is off the plate (it
    relaxes, as the viscoelastic column and the simulation have it), so with one the samples are decided in
    order: each sample's element force is the one the previous decisions leave."""
    vehicle = signals.vehicle
    load = vehicle.static_wheel_load_N
    masks = []
    for corner in signals.corners:
        force = (vehicle.tyre_stiffness_N_per_m + stiffness_change) * corner.tyre_deflection_smooth_m
        if dashpot:
            force = force + dashpot * corner.tyre_rate_m_s
        if not maxwell:
            masks.append((force > load).astype(float))
            continue
        # the bilinear Maxwell recursion of EquationSignals.maxwell_regressor with a gated input
        dt = signals.sample_time_s
        tau = vehicle.maxwell_time_constant_s(dt)
        pole, gain = (2.0 * tau - dt) / (2.0 * tau + dt), dt / (2.0 * tau + dt)
        rates = corner.tyre_rate_m_s.tolist()
        spring = force.tolist()
        airborne = [0.0] * len(rates)
        state, previous_input = 0.0, 0.0
        for k, rate in enumerate(rates):
            relaxed = pole * state + gain * previous_input
            driven = relaxed + gain * rate
            if spring[k] + maxwell * driven > load:
                airborne[k], state, previous_input = 1.0, relaxed, 0.0
            else:
                state, previous_input = driven, rate
        masks.append(np.array(airborne))
    return masks


def _cached(cache: dict, lock: threading.Lock, key: tuple, make: Callable[[], object], entries: int) -> Any:
    """cache[key], made first if missing (outside the lock: two threads may make the same value, which is a
    deterministic function of the key); the least recently used entries beyond `entries` are forgotten."""
    with lock:
        found = key in cache
        value = cache.pop(key) if found else None
        if found:
            cache[key] = value
    if not found:
        value = make()
        with lock:
            cache[key] = value
            while len(cache) > entries:
                del cache[next(iter(cache))]
    return value


def _base_system(
    reference: Reference, corrections: ChannelCorrections
) -> tuple[tuple, LinearResiduals, EquationSignals]:
    """The paper's system (no family columns) on the recording as `corrections` correct it; built once per
    Reference and reused. The key identifies it for the columns' cache (zero parameters leave a channel as
    it is, so they are left out of the key)."""
    key = tuple(
        tuple(sorted((name, value) for name, value in table.items() if value))
        for table in (
            corrections.delay_s,
            corrections.offset_m,
            corrections.lag_s,
            corrections.average_s,
            corrections.gain_error,
        )
    )

    def make() -> tuple[LinearResiduals, EquationSignals]:
        recording = corrections.apply(reference.recording)
        settings = reference.settings
        base = build(
            recording,
            reference.vehicle,
            TyreModel.SPRING,
            settings.points,
            settings.nsample,
            reference.filters,
            reference.grids,
        )
        return base, EquationSignals(recording, reference.vehicle, base)

    base, signals = _cached(reference.built, reference.lock, key, make, BUILD_CACHE_ENTRIES)
    return key, base, signals


def _build(
    reference: Reference,
    structure: ModelStructure,
    corrections: ChannelCorrections,
    airborne: list[np.ndarray] | None,
    tyre: tuple[float, float, float],
) -> tuple[LinearResiduals, EquationSignals, list[np.ndarray]]:
    """The extended system of `structure` (tyre: the fitted tyre's dashpot, Maxwell damping and rate change,
    from which the airborne samples of tyre_liftoff are decided when `airborne` is None)."""
    key, base, signals = _base_system(reference, corrections)
    corners = len(signals.corners)
    liftoff = structure.has(EffectName.TYRE_LIFTOFF)
    if airborne is None:
        airborne = (
            _airborne(signals, *tyre) if liftoff else [np.zeros(signals.recording.time_s.size)] * corners
        )
    # the columns depend on where the tyre is off the plate only with tyre_liftoff (else nowhere)
    where = tuple(a.tobytes() for a in airborne) if liftoff else None
    columns: dict[str, np.ndarray] = {}
    offset = base.offset.copy()
    for effect in structure.effects:
        entry = CATALOG[effect.name]
        effect_columns, change = _cached(
            reference.columns,
            reference.lock,
            (key, effect, where),
            lambda entry=entry, effect=effect: (
                entry.columns(effect, signals, airborne, reference.knots_m, reference.identified),
                entry.offset_change(signals, airborne),
            ),
            COLUMN_CACHE_ENTRIES,
        )
        columns.update(effect_columns)
        if change is not None:
            offset = offset + change
    return with_columns(base, columns, offset), signals, airborne


def _tyre_coefficients(system: LinearResiduals, theta: np.ndarray) -> tuple[float, float, float]:
    """The fitted tyre's dashpot, Maxwell damping and stiffness correction (0 where the model lacks one)."""
    names = system.parameter_names

    def value(name: str) -> float:
        return float(theta[names.index(name)]) if name in names else 0.0

    return value("tyre_dashpot_Ns_per_m"), value("maxwell_damping_Ns_per_m"), value(TYRE_RATE_UNKNOWN)


def feasible(kinds: list[str], values: np.ndarray) -> np.ndarray:
    """Channel parameter values moved into what a sensor can be: delays, lags and averaging windows in
    [0, MAX_DELAY_S], gain errors above −50%."""
    values = np.array(values, dtype=float)
    for j, kind in enumerate(kinds):
        if kind in NONNEGATIVE:
            values[j] = float(np.clip(values[j], 0.0, MAX_DELAY_S))
        elif kind == "gain":
            values[j] = max(values[j], -0.5)
    return values


def start_from(system: LinearResiduals, warm: FittedModel) -> np.ndarray:
    """θ of a similar model, matched by unknown name (new unknowns start at zero)."""
    known = dict(zip(warm.system.parameter_names, warm.theta, strict=True))
    return np.array([known.get(name, 0.0) for name in system.parameter_names])


def build_at(
    reference: Reference, current: FittedModel, structure: ModelStructure, values: np.ndarray
) -> tuple[LinearResiduals, EquationSignals, list[np.ndarray]]:
    """The extended system of `structure` with channel parameters `values`, its airborne samples (with
    tyre_liftoff) decided by the current model's tyre; airborne is [] without tyre_liftoff."""
    tyre = _tyre_coefficients(current.system, current.theta)
    system, signals, airborne = _build(
        reference, structure, corrections_of(structure.channel_parameters, values), None, tyre
    )
    return system, signals, airborne if structure.has(EffectName.TYRE_LIFTOFF) else []


def minimise(
    system: LinearResiduals, initial: np.ndarray | None, tolerance: float = 1e-10
) -> tuple[np.ndarray, float]:
    """θ minimising the paper's objective, and the objective: estimator.solvers.exact's IRLS handing over to
    Newton steps, to `tolerance`, as identify does."""
    solution = solve_exact(system, tolerance, initial=initial, certify=False)
    return solution.theta, solution.objective


def channel_jacobian(
    reference: Reference,
    model: FittedModel,
    rows: np.ndarray | None = None,
    which: list[int] | None = None,
) -> dict[str, np.ndarray]:
    """Per Gauss-Newton parameter of the model (those at the indices `which`, when given), the change of its
    equation residual per unit of the parameter at the fitted θ (finite differences of GAUSS_NEWTON_STEP; the
    airborne samples held), restricted to `rows` when given. Also what the Wald test of a channel family
    treats as the family's columns."""
    parameters = model.structure.channel_parameters
    tyre = _tyre_coefficients(model.system, model.theta)
    airborne = model.airborne or None
    base = restrict(model.system, rows) if rows is not None else model.system
    base_residual = base.residuals(model.theta)
    jacobian = {}
    for j, (effect, kind) in enumerate(parameters):
        if which is not None and j not in which:
            continue
        values = np.array(model.channel_values, dtype=float)
        values[j] += GAUSS_NEWTON_STEP[kind]
        moved, _, _ = _build(reference, model.structure, corrections_of(parameters, values), airborne, tyre)
        moved = restrict(moved, rows) if rows is not None else moved
        jacobian[f"{kind} of {effect.label}"] = (
            moved.residuals(model.theta) - base_residual
        ) / GAUSS_NEWTON_STEP[kind]
    return jacobian


def fit(
    reference: Reference,
    structure: ModelStructure,
    rows: np.ndarray | None = None,
    warm: FittedModel | None = None,
    iterations: int = GAUSS_NEWTON_ITERATIONS,
) -> FittedModel:
    """Identify `structure` on the reference recording, using only the selected samples where `rows` is
    True (all when None). warm: a fitted model of a similar structure to start from (its unknowns and
    channel parameters, matched by family and kind; new ones start at zero). iterations: Gauss-Newton steps
    at most (channel families). A step that raises the objective is halved (at most HALVINGS times, then
    the fit keeps its best point): a delay and a lag of one channel are nearly collinear, and a full step
    clipped at zero can overshoot."""
    parameters = structure.channel_parameters
    kinds = [kind for _, kind in parameters]
    start = dict(zip(warm.structure.channel_parameters, warm.channel_values, strict=True)) if warm else {}
    values = np.array([start.get(p, 0.0) for p in parameters], dtype=float)
    liftoff = structure.has(EffectName.TYRE_LIFTOFF)
    tyre = (0.0, 0.0, 0.0)
    previous, best, step = warm, None, np.zeros(len(parameters))
    final_pass, steps, halvings = False, 0, 0
    while True:
        system, signals, airborne = _build(
            reference, structure, corrections_of(parameters, values), None, tyre
        )
        used = restrict(system, rows) if rows is not None else system
        theta, objective = minimise(used, start_from(used, previous) if previous else None)
        model = FittedModel(
            structure,
            reference.vehicle,
            theta,
            system,
            signals,
            values.copy(),
            airborne if liftoff else [],
            objective,
            reference.knots_m,
        )
        if parameters and best is not None and objective > best.objective:
            if halvings == HALVINGS:
                return best
            halvings, step = halvings + 1, step / 2.0
            values = feasible(kinds, best.channel_values + step)
            continue
        best, previous, halvings = model, model, 0
        tyre = _tyre_coefficients(system, theta)
        if final_pass or (not parameters and not (liftoff and steps == 0)):
            return model
        steps += 1
        if not parameters:
            continue  # once more with the airborne samples of the fitted tyre force
        moved = bounded_step(used, theta, channel_jacobian(reference, model, rows), kinds, values)
        step, values = moved - values, moved
        small = all(abs(d) < GAUSS_NEWTON_TOLERANCE[k] for d, k in zip(step, kinds, strict=True))
        affine = all(k == "offset" for k in kinds) and not liftoff
        final_pass = small or affine or steps == iterations


def bounded_step(
    used: LinearResiduals,
    theta: np.ndarray,
    jacobian: dict[str, np.ndarray],
    kinds: list[str],
    values: np.ndarray,
) -> np.ndarray:
    """The channel values after one Gauss-Newton step, θ solved with them, under the bounds of `feasible`
    (an active-set step): a parameter the step would push past its bound is held at the bound and the
    others are solved again with its change in the offset. Clipping afterwards instead would keep the
    others' share of a combined move: a delay and an averaging window of one channel fitted to a pure
    3 ms delay step to +10 ms and −7 ms, and clipping the window at zero left the delay at 10 ms."""
    names = list(jacobian)
    fixed: dict[int, float] = {}
    while True:
        free = [j for j in range(len(names)) if j not in fixed]
        offset = used.offset + sum((jacobian[names[j]] * change for j, change in fixed.items()), 0.0)
        augmented = with_columns(used, {names[j]: jacobian[names[j]] for j in free}, offset)
        solved = minimise(augmented, np.concatenate([theta, np.zeros(len(free))]), 1e-8)[0]
        increment = np.zeros(len(names))
        increment[free] = solved[used.n_params :]
        for j, change in fixed.items():
            increment[j] = change
        moved = feasible(kinds, values + increment)
        clipped = [j for j in free if moved[j] != values[j] + increment[j]]
        if not clipped or len(free) == 1:
            return moved
        for j in clipped:
            fixed[j] = moved[j] - values[j]


def fit_added(
    reference: Reference, current: FittedModel, family: EffectInstance, start: FittedModel
) -> FittedModel:
    """The current model with `family` added, identified from `start` (its one-step model), or from the
    current model when that ends worse than the current model: a larger model cannot fit worse, and a
    one step of nearly collinear channel parameters (a delay and a lag) can start far off."""
    structure = current.structure.with_effect(family)
    model = fit(reference, structure, warm=start)
    return model if model.objective <= current.objective else fit(reference, structure, warm=current)
