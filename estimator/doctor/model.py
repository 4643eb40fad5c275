"""A model with candidate effects added, and how it is fitted.

ModelStructure says which effects the model has beyond the vehicle file's constants (the starting tyre model
counts: kelvin-voigt starts with tyre_damping, maxwell with tyre_viscoelastic). fit() identifies it:

1. the recording is corrected for the model's channel effects (a delayed channel is advanced by its delay,
   an offset is subtracted);
2. the paper's equations are built on it (estimator.equations, with the damper grid and filters of the
   uncorrected recording so that every candidate shares its unknowns) and each force effect appends its
   column (estimator.doctor.catalog);
3. the paper's objective is minimised exactly (estimator.solvers.exact). Channel parameters (delays,
   offsets) are found by Gauss-Newton steps: the residual's change per unit of each channel parameter is
   taken by finite differences at the current solution, appended as columns, solved jointly, repeated.
   With tyre_liftoff the airborne samples come from the fitted tyre force and are re-determined once.
4. with coulomb_friction, in two stages: the friction is identified with the damper curve one line across
   the friction band (friction_grids, friction_constraints: otherwise the curve makes the step itself);
   then, the friction, channel parameters and airborne samples held, the rest is identified again with the
   curve on the reference grid with low-speed knots (_free_curve). The first stage is kept with the model
   (FittedModel.constrained): the friction's standard error and the comparison with a base on the friction
   grid come from it; the model simulated has the curve the data support (a damper dead band inside the
   band, as the FSAE s5 table has, is what one line across it cannot follow).

Speed: a diagnosis fits a hundred or so models of one recording, most of them on the same corrected
recording, so the equations built on it and the effects' columns are kept per Reference (a small
least-recently-used cache: building them, low-pass filters and damper basis, was half of a fit), and every
solve hands IRLS over to Newton steps once it is near the optimum (_minimise).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from estimator.damper import PiecewiseLinearCurve
from estimator.doctor.catalog import (
    CATALOG,
    FRICTION_BAND_M_S,
    MAX_DELAY_S,
    SIGNIFICANCE_Z,
    STIFFNESS_UNKNOWNS,
    EffectInstance,
    EffectName,
    FitContext,
)
from estimator.doctor.columns import EquationSignals, restrict, with_columns
from estimator.doctor.sensors import ChannelCorrections
from estimator.equations import LinearResiduals, build
from estimator.errors import InvalidValueError
from estimator.recording import Recording
from estimator.signals import FilterChoice
from estimator.solvers.exact import solve_exact
from estimator.uncertainty import confidence_intervals
from estimator.vehicle import TyreModel, VehicleConstant, VehicleParameters

GAUSS_NEWTON_ITERATIONS = 4
GAUSS_NEWTON_STEP = {"delay": 5e-4, "offset": 1e-4}
"""Finite-difference step of each kind of channel parameter (s, m)."""
GAUSS_NEWTON_TOLERANCE = {"delay": 2e-6, "offset": 1e-7}


@dataclass(frozen=True)
class ModelStructure:
    """The effects a model has beyond the vehicle file's constants, in the order they were added."""

    effects: tuple[EffectInstance, ...] = ()
    free_curve: bool = True
    """With coulomb_friction: the curve refitted on the reference grid with the friction held (fit's second
    stage); False where the output preferred the first stage's curve (_Doctor.play)."""

    def with_effect(self, effect: EffectInstance) -> ModelStructure:
        return replace(self, effects=(*self.effects, effect))

    def has(self, name: EffectName) -> bool:
        return any(e.name is name for e in self.effects)

    @property
    def channel_effects(self) -> list[EffectInstance]:
        return [e for e in self.effects if CATALOG[e.name].channel_kind is not None]

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


@dataclass(frozen=True)
class FitSettings:
    points: int | None = None
    """Damper curve points (default 20 for a quarter car, 10 per side for an axle)."""
    nsample: int | None = 5000
    low_speed_knots: bool = False
    """The uniform grid gets knots at 0 and ±LOW_SPEED_KNOTS_M_S too (low_speed_grids)."""


@dataclass
class FittedModel:
    """A structure identified on a recording: θ of the extended system (built on the corrected recording)."""

    structure: ModelStructure
    vehicle: VehicleParameters
    theta: np.ndarray
    system: LinearResiduals
    """The extended system on all selected samples (also when the fit used only some of them)."""
    signals: EquationSignals
    channel_values: dict[EffectInstance, float]
    """Fitted delay (s) or offset (m) per channel effect."""
    airborne: list[np.ndarray]
    """Per corner, where the fitted tyre force would pull on the plate (only with tyre_liftoff)."""
    objective: float
    curve_override: tuple[PiecewiseLinearCurve, ...] | None = None
    """Damper curves to simulate instead of the fitted points (the expected-gap truth's smooth curves)."""
    constrained: FittedModel | None = None
    """With coulomb_friction: the first stage of the two-stage fit (fit), the friction identified with the
    curve on the friction grid and constraint. This model keeps its friction and has the curve refitted on
    the reference grid; the standard errors and the like-with-like comparisons come from the first stage."""

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
        delays = {e.channel: v for e, v in self.channel_values.items() if e.name is EffectName.CHANNEL_DELAY}
        offsets = {e.channel: v for e, v in self.channel_values.items() if e.name is EffectName.SENSOR_OFFSET}
        return ChannelCorrections(delays, offsets)  # type: ignore[arg-type]

    def residuals(self) -> np.ndarray:
        """(equations, selected samples) residual forces, N."""
        return self.system.residuals(self.theta)

    @property
    def spring_stiffness_N_per_m(self) -> float:
        """K_s as this model has it: the stated rate plus its fitted correction (if it has one)."""
        return float(self.vehicle.spring_stiffness_N_per_m or 0.0) + self.value(
            STIFFNESS_UNKNOWNS[VehicleConstant.SPRING]
        )

    @property
    def tyre_stiffness_N_per_m(self) -> float:
        """K_t as this model has it: the stated rate plus its fitted correction (if it has one)."""
        return float(self.vehicle.tyre_stiffness_N_per_m or 0.0) + self.value(
            STIFFNESS_UNKNOWNS[VehicleConstant.TYRE]
        )

    def standard_errors(self, names: list[str], rows: np.ndarray | None = None) -> dict[str, float]:
        """Standard errors of the named unknowns of θ (those it has; channel parameters have none) from the
        samples where `rows` is True (all when None): sandwich covariance with a block long-run variance
        of the score (estimator.uncertainty)."""
        if self.constrained is not None:
            return self.constrained.standard_errors(names, rows)
        present = [n for n in names if n in self.system.parameter_names]
        if not present:
            return {}
        system = restrict(self.system, rows) if rows is not None else self.system
        intervals = confidence_intervals(system, self.theta, self.signals.sample_time_s)
        return {n: float(intervals.standard_error[system.parameter_names.index(n)]) for n in present}

    def _standard_errors(self) -> dict[str, float]:
        """Standard errors of the stiffness corrections and the friction the model has (the unknowns the
        catalog tests against them); empty when it has none."""
        return self.standard_errors([*STIFFNESS_UNKNOWNS.values(), "coulomb_friction_N"])

    def context(self) -> FitContext:
        dt = self.signals.sample_time_s
        airborne = float(np.mean([a.mean() for a in self.airborne])) if self.airborne else 0.0
        peak = max(float(np.quantile(np.abs(c.deflection_m), 0.999)) for c in self.signals.corners)
        return FitContext(
            spring_stiffness=self.spring_stiffness_N_per_m,
            static_wheel_load_N=self.vehicle.static_wheel_load_N,
            maxwell_time_constant_s=self.vehicle.maxwell_time_constant_s(dt),
            peak_deflection_m=peak,
            airborne_fraction=airborne,
            stated_stiffness_N_per_m={
                VehicleConstant.SPRING: float(self.vehicle.spring_stiffness_N_per_m or 0.0),
                VehicleConstant.TYRE: float(self.vehicle.tyre_stiffness_N_per_m or 0.0),
            },
            standard_error=self._standard_errors(),
            peak_damper_force_N=max(float(np.max(np.abs(c.force_N))) for c in self.curves),
            sample_time_s=dt,
        )

    def effect_values(self, effect: EffectInstance) -> dict[str, float]:
        """The fitted unknowns of one effect, by name (SI units)."""
        if effect.name is EffectName.CHANNEL_DELAY:
            return {"delay_s": self.channel_values[effect]}
        if effect.name is EffectName.SENSOR_OFFSET:
            return {"offset_m": self.channel_values[effect]}
        if effect.name is EffectName.TYRE_VISCOELASTIC:
            return {"maxwell_damping_Ns_per_m": self.maxwell_damping_Ns_per_m}
        names = {
            EffectName.SPRING_STIFFNESS: STIFFNESS_UNKNOWNS[VehicleConstant.SPRING],
            EffectName.TYRE_STIFFNESS: STIFFNESS_UNKNOWNS[VehicleConstant.TYRE],
            EffectName.TYRE_DAMPING: "tyre_dashpot_Ns_per_m",
            EffectName.COULOMB_FRICTION: "coulomb_friction_N",
            EffectName.PROGRESSIVE_SPRING: "cubic_spring_N_per_m3",
            EffectName.ANTI_ROLL_BAR: "anti_roll_bar_N_per_m",
        }
        return {names[effect.name]: self.value(names[effect.name])} if effect.name in names else {}

    def parameters(self, effect: EffectInstance) -> dict[str, float | str]:
        return CATALOG[effect.name].report(effect, self.effect_values(effect), self.context())

    def implausible(
        self, effect: EffectInstance, significance_z: float | None = SIGNIFICANCE_Z
    ) -> str | None:
        """Why the fitted effect cannot be what it says (catalog's Effect.implausible), with the value tested
        against significance_z of its standard errors (None: not tested)."""
        context = self.context()
        if significance_z is None:
            context = replace(context, standard_error={})
        else:
            context = replace(context, significance_z=significance_z)
        return CATALOG[effect.name].implausible(self.effect_values(effect), context)


def first_stage(model: FittedModel) -> FittedModel:
    """The model as it is compared with a base on the friction grid: its first stage when it has one
    (FittedModel.constrained), else itself."""
    return model.constrained if model.constrained is not None else model


BUILD_CACHE_ENTRIES = 8
"""Equation systems a Reference keeps (the most recently used): every candidate of a round and its held-out
and half-sweep fits start from the same corrected recording, so they share one build."""
COLUMN_CACHE_ENTRIES = 32
"""Effect columns a Reference keeps (the most recently used)."""


@dataclass(frozen=True)
class Reference:
    """What every fit of one recording shares: the damper grid(s) and filters of the uncorrected recording,
    and the equation systems built on it so far (`built`, see _build)."""

    recording: Recording
    vehicle: VehicleParameters
    settings: FitSettings
    grids: list[np.ndarray]
    filters: FilterChoice
    built: dict[tuple, tuple[LinearResiduals, EquationSignals]] = field(
        default_factory=dict, compare=False, repr=False
    )
    columns: dict[tuple, tuple[dict[str, np.ndarray], np.ndarray | None]] = field(
        default_factory=dict, compare=False, repr=False
    )
    lock: threading.Lock = field(default_factory=threading.Lock, compare=False, repr=False)
    """Guards the caches: the doctor fits candidates in parallel threads."""

    @staticmethod
    def of(recording: Recording, vehicle: VehicleParameters, settings: FitSettings) -> Reference:
        if vehicle.is_axle != recording.is_axle:
            kind = "axle" if vehicle.is_axle else "quarter-car"
            raise InvalidValueError(
                f"the vehicle file is for a {kind} model but the recording's channels are not"
            )
        base = build(recording, vehicle, TyreModel.SPRING, settings.points, settings.nsample)
        grids = low_speed_grids(base.grids_m_s) if settings.low_speed_knots else base.grids_m_s
        return Reference(recording, vehicle, settings, grids, base.filters)


LOW_SPEED_KNOTS_M_S = (0.0, 0.005, 0.01)
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


def _same_size(grids: list[np.ndarray], keep_m_s: float | None = None) -> list[np.ndarray]:
    """The grids with the widest intervals of the shorter ones halved until all have as many knots (an axle's
    two curves must); the interval starting at −keep_m_s is not halved."""
    size = max(g.size for g in grids)
    changed = []
    for grid in grids:
        while grid.size < size:
            widths = np.diff(grid)
            if keep_m_s is not None:
                widths = np.where(np.isclose(grid[:-1], -keep_m_s), 0.0, widths)
            widest = int(np.argmax(widths))
            grid = np.insert(grid, widest + 1, 0.5 * (grid[widest] + grid[widest + 1]))
        changed.append(grid)
    return changed


def friction_grids(grids: list[np.ndarray], band_m_s: float = FRICTION_BAND_M_S) -> list[np.ndarray]:
    """The damper grids of a model with coulomb_friction: knots at ±band_m_s and none between (the curve is
    one line there, so that it cannot make the friction step itself), the other knots as they were. An
    axle's two grids keep the same number of knots (the longer intervals of the shorter one are halved)."""
    changed = []
    for grid in grids:
        outside = grid[np.abs(grid) >= band_m_s]
        edges = [v for v in (-band_m_s, band_m_s) if grid[0] < v < grid[-1]]
        changed.append(np.unique(np.concatenate([outside, edges])))
    return _same_size(changed, band_m_s)


def friction_constraints(system: LinearResiduals, band_m_s: float = FRICTION_BAND_M_S) -> np.ndarray:
    """Rows a with a·θ = 0 (one per damper curve, as many columns as θ): the curve's slope across the band
    ±band_m_s is the mean of its slopes on the intervals either side. With knots at ±band only (see
    friction_grids) the curve could still step from −F to +F across the band; the constraint leaves it the
    slope a smooth curve has there, so only the friction term can step (on an independent recording with 98 N
    of friction: 104 N fitted with the constraint, 121 N without; either way the fast half of the sweep, with
    zero crossings of a few ms, sees less of the friction than the slow half)."""
    rows = []
    for grid, part in zip(system.grids_m_s, system.curve_slices, strict=True):
        low = np.nonzero(np.isclose(grid, -band_m_s, rtol=0.0, atol=1e-12))[0]
        if low.size == 0 or low[0] < 1 or low[0] + 2 >= grid.size:
            continue
        i = int(low[0])
        if not np.isclose(grid[i + 1], band_m_s, rtol=0.0, atol=1e-12):
            continue
        width, left, right = 2.0 * band_m_s, grid[i] - grid[i - 1], grid[i + 2] - grid[i + 1]
        row = np.zeros(system.n_params)
        row[part.start + i - 1] = 0.5 / left
        row[part.start + i] = -1.0 / width - 0.5 / left
        row[part.start + i + 1] = 1.0 / width + 0.5 / right
        row[part.start + i + 2] = -0.5 / right
        rows.append(row)
    return np.array(rows).reshape(len(rows), system.n_params)


def _minimise(
    system: LinearResiduals, initial: np.ndarray | None, tolerance: float
) -> tuple[np.ndarray, float]:
    """θ minimising the paper's objective, and the objective: estimator.solvers.exact's IRLS handing over to
    Newton steps, to `tolerance`, as identify does (a median 27 weighted normal matrices per fit of the
    doctor to 1e-10 by IRLS alone)."""
    solution = solve_exact(system, tolerance, initial=initial, certify=False)
    return solution.theta, solution.objective


def _solve(
    system: LinearResiduals,
    constraints: np.ndarray,
    initial: np.ndarray | None,
    tolerance: float = 1e-10,
) -> tuple[np.ndarray, float]:
    """θ minimising the paper's objective subject to constraints·θ = 0 (rows padded with zeros to θ's
    length), and the objective. Each row is eliminated through its largest coefficient (θ = N·z over the
    others), so the problem stays the same convex one on fewer unknowns."""
    p = system.n_params
    if constraints.shape[0] == 0:
        return _minimise(system, initial, tolerance)
    rows = np.zeros((constraints.shape[0], p))
    rows[:, : constraints.shape[1]] = constraints
    pivots = [int(np.argmax(np.abs(r))) for r in rows]
    keep = [k for k in range(p) if k not in pivots]
    basis = np.zeros((p, len(keep)))
    basis[keep, np.arange(len(keep))] = 1.0
    for row, pivot in zip(rows, pivots, strict=True):
        basis[pivot] = -row[keep] / row[pivot]
    reduced = system.reparametrised(basis, [system.parameter_names[k] for k in keep])
    start = None if initial is None else np.asarray(initial)[keep]
    theta, objective = _minimise(reduced, start, tolerance)
    return basis @ theta, objective


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


GridKind = Literal["reference", "friction", "low_speed"]
"""The damper grids of a build: the reference grids, the friction grids (friction_grids) or the reference
grids with low-speed knots (low_speed_grids; the reference grids when they have them already)."""


def _grids(reference: Reference, kind: GridKind) -> list[np.ndarray]:
    if kind == "low_speed":
        return reference.grids if reference.settings.low_speed_knots else low_speed_grids(reference.grids)
    return friction_grids(reference.grids) if kind == "friction" else reference.grids


def _base_system(
    reference: Reference, corrections: ChannelCorrections, kind: GridKind
) -> tuple[tuple, LinearResiduals, EquationSignals]:
    """The paper's system (no effect columns) on the recording as `corrections` correct it, on the grids
    of `kind`; built once per Reference and reused (the low-pass filters and the damper basis
    are most of a fit's time otherwise). The key identifies it for the effect columns' cache."""
    # a zero delay or offset leaves the channel as it is (ChannelCorrections.correct), so it is left out of
    # the key: the candidates' first trial at zero then reuses the uncorrected build (bit for bit the same)
    key = (
        tuple(sorted((name, value) for name, value in corrections.delay_s.items() if value)),
        tuple(sorted((name, value) for name, value in corrections.offset_m.items() if value)),
        tuple(sorted((name, value) for name, value in corrections.lag_s.items() if value)),
        tuple(sorted((name, value) for name, value in corrections.average_s.items() if value)),
        tuple(sorted((name, value) for name, value in corrections.gain_error.items() if value)),
        kind,
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
            _grids(reference, kind),
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
    friction_grid: bool = False,
    free_grid: bool = False,
) -> tuple[LinearResiduals, EquationSignals, list[np.ndarray]]:
    """The extended system of `structure`, on the friction grids with coulomb_friction or friction_grid, on
    the grids with low-speed knots with free_grid (a friction model's second stage, _free_curve)."""
    kind: GridKind = "reference"
    if free_grid:
        kind = "low_speed"
    elif friction_grid or structure.has(EffectName.COULOMB_FRICTION):
        kind = "friction"
    key, base, signals = _base_system(reference, corrections, kind)
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
            lambda entry=entry: (entry.columns(signals, airborne), entry.offset_change(signals, airborne)),
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

    return (
        value("tyre_dashpot_Ns_per_m"),
        value("maxwell_damping_Ns_per_m"),
        value(STIFFNESS_UNKNOWNS[VehicleConstant.TYRE]),
    )


def _corrections(effects: list[EffectInstance], values: np.ndarray) -> ChannelCorrections:
    delays, offsets = {}, {}
    for effect, value in zip(effects, values, strict=True):
        target = delays if effect.name is EffectName.CHANNEL_DELAY else offsets
        target[str(effect.channel)] = float(value)
    return ChannelCorrections(delays, offsets)


def _initial(system: LinearResiduals, warm: FittedModel | None) -> np.ndarray | None:
    """θ of a similar model, matched by unknown name (new unknowns start at zero)."""
    if warm is None:
        return None
    known = dict(zip(warm.system.parameter_names, warm.theta, strict=True))
    return np.array([known.get(name, 0.0) for name in system.parameter_names])


def fit(
    reference: Reference,
    structure: ModelStructure,
    rows: np.ndarray | None = None,
    warm: FittedModel | None = None,
    iterations: int = GAUSS_NEWTON_ITERATIONS,
    friction_grid: bool = False,
    two_stage: bool = True,
) -> FittedModel:
    """Identify `structure` on the reference recording, using only the selected samples where `rows` is
    True (all when None). warm: a fitted model of a similar structure to start from (its unknowns and
    channel parameters; new ones start at zero). iterations: Gauss-Newton steps at most (channel effects).
    friction_grid: the damper curve on the grid and under the constraint a model with coulomb_friction has
    (friction_grids, friction_constraints) even without the friction term: the base a friction candidate is
    compared with, so that the comparison measures the friction term and not the coarser curve near zero.
    two_stage: a structure with coulomb_friction is fitted in two stages (_free_curve): the friction
    identified on the friction grid and constraint, then the curve refitted on the reference grid with the
    friction held (False: the first stage only)."""
    friction = friction_grid or structure.has(EffectName.COULOMB_FRICTION)
    channel_effects = structure.channel_effects
    kinds = [CATALOG[e.name].channel_kind for e in channel_effects]
    start = warm.channel_values if warm is not None else {}
    values = np.array([start.get(e, 0.0) for e in channel_effects], dtype=float)
    liftoff = structure.has(EffectName.TYRE_LIFTOFF)
    tyre = (0.0, 0.0, 0.0)
    final_pass = False
    previous = first_stage(warm) if warm is not None else None
    for iteration in range(iterations + 1):
        corrections = _corrections(channel_effects, values)
        system, signals, airborne = _build(reference, structure, corrections, None, tyre, friction)
        used = restrict(system, rows) if rows is not None else system
        constraints = friction_constraints(used) if friction else None
        if constraints is None:
            constraints = np.zeros((0, used.n_params))
        theta, objective = _solve(used, constraints, _initial(used, previous))
        tyre = _tyre_coefficients(system, theta)
        previous = FittedModel(structure, reference.vehicle, theta, system, signals, {}, [], objective)
        if final_pass:
            break
        if not channel_effects:
            if liftoff and iteration == 0:
                continue  # once more with the airborne samples of the fitted tyre force
            break
        base_residual = used.residuals(theta)
        jacobian = {}
        for j, (effect, kind) in enumerate(zip(channel_effects, kinds, strict=True)):
            step = np.zeros_like(values)
            step[j] = GAUSS_NEWTON_STEP[str(kind)]
            moved, _, _ = _build(
                reference, structure, _corrections(channel_effects, values + step), airborne, tyre, friction
            )
            moved_used = restrict(moved, rows) if rows is not None else moved
            jacobian[f"step of {effect.label}"] = (moved_used.residuals(theta) - base_residual) / step[j]
        augmented = with_columns(used, jacobian, used.offset)
        initial = np.concatenate([theta, np.zeros(len(jacobian))])
        increment = _solve(augmented, constraints, initial, 1e-8)[0][used.n_params :]
        values = values + increment
        for j, kind in enumerate(kinds):
            if kind == "delay":
                values[j] = float(np.clip(values[j], 0.0, MAX_DELAY_S))
        small = all(abs(d) < GAUSS_NEWTON_TOLERANCE[str(k)] for d, k in zip(increment, kinds, strict=True))
        affine = all(k == "offset" for k in kinds) and not liftoff
        final_pass = small or affine or iteration == iterations - 1
    model = FittedModel(
        structure=structure,
        vehicle=reference.vehicle,
        theta=theta,
        system=system,
        signals=signals,
        channel_values={e: float(v) for e, v in zip(channel_effects, values, strict=True)},
        airborne=airborne if liftoff else [],
        objective=objective,
    )
    if two_stage and structure.free_curve and structure.has(EffectName.COULOMB_FRICTION):
        return _free_curve(reference, model, rows, warm)
    return model


FRICTION_UNKNOWN = "coulomb_friction_N"


def _free_curve(
    reference: Reference, constrained: FittedModel, rows: np.ndarray | None, warm: FittedModel | None
) -> FittedModel:
    """The second stage of a model with coulomb_friction: the friction (N), channel parameters and airborne
    samples of the first stage (`constrained`, on the friction grid and constraint, which is what makes the
    friction identifiable) held, the rest identified again with the damper curve on the reference grid. One
    straight line across the friction band cannot follow a damper whose dead band and steep rise lie inside
    it (FSAE s5: a few newtons up to 4 mm/s, 350 N at 23 mm/s); the model simulated, named and carried into
    later rounds has the curve the data support."""
    structure = constrained.structure
    airborne = constrained.airborne if structure.has(EffectName.TYRE_LIFTOFF) else None
    system, signals, _ = _build(
        reference, structure, constrained.corrections, airborne, (0.0, 0.0, 0.0), free_grid=True
    )
    used = restrict(system, rows) if rows is not None else system
    index = used.parameter_names.index(FRICTION_UNKNOWN)
    friction = constrained.value(FRICTION_UNKNOWN)
    keep = [k for k in range(used.n_params) if k != index]
    held = used.with_unknown_held(FRICTION_UNKNOWN, friction)
    same_grid = warm is not None and all(
        np.array_equal(a, b) for a, b in zip(warm.system.grids_m_s, system.grids_m_s, strict=True)
    )
    start = _initial(used, warm) if same_grid else None
    reduced, objective = _minimise(held, None if start is None else start[keep], 1e-10)
    return replace(
        constrained,
        theta=np.insert(reduced, index, friction),
        system=system,
        signals=signals,
        objective=objective,
        constrained=constrained,
    )
