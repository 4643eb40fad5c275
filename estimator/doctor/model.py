"""A model with effect families added, and the equations it is identified on (estimator.doctor.fitting
fits it).

ModelStructure says which families a model has beyond the vehicle file's constants (the starting tyre model
counts: kelvin-voigt starts with tyre_damping, maxwell with tyre_viscoelastic). Its equations:

1. the recording is corrected for the model's channel families (estimator.laser_channels);
2. the paper's equations are built on it (estimator.equations, with the damper grid and filters of the
   uncorrected recording, so every candidate shares its unknowns; the grid has knots at 0 and ±10 mm/s,
   low_speed_grids, so that the curve follows a damper's low-speed rise and a friction step is only what
   the curve cannot make) and each force family appends its columns (estimator.doctor.catalog).

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
    SPRING_RATE_UNKNOWN,
    TYRE_RATE_UNKNOWN,
    EffectInstance,
    EffectName,
    hinge_knots_m,
    hinge_unknowns,
    stribeck_velocity_m_s,
)
from estimator.doctor.columns import EquationSignals, with_columns
from estimator.equations import LinearResiduals, build
from estimator.errors import InvalidValueError
from estimator.laser_channels import ChannelCorrections
from estimator.recording import Recording
from estimator.signals import FilterChoice
from estimator.vehicle import TyreModel, VehicleConstant, VehicleParameters

__all__ = ["ChannelCorrections", "FitSettings", "FittedModel", "ModelStructure", "Reference"]


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


LOW_SPEED_KNOTS_M_S = (0.0, 0.01)
"""Suspension velocities (m/s) at which a grid with low-speed knots gets a knot (at ± each), evenly spaced."""


@dataclass(frozen=True)
class FitSettings:
    points: int | None = None
    """Damper curve points (default 20 for a quarter car, 10 per side for an axle), before low-speed knots."""
    nsample: int | None = 5000
    low_speed_knots_m_s: tuple[float, ...] = LOW_SPEED_KNOTS_M_S
    """The low-speed knots (low_speed_grids); a bootstrap truth has them finer (estimator.doctor.expected)."""


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
        grids = low_speed_grids(base.grids_m_s, settings.low_speed_knots_m_s)
        return Reference(recording, vehicle, settings, grids, base.filters, knots, identified)


LOW_SPEED_CLEARANCE = 0.5
"""A uniform knot closer to a low-speed knot than this share of the low-speed knots' spacing gives way."""


def low_speed_grids(
    grids: list[np.ndarray], knots_m_s: tuple[float, ...] = LOW_SPEED_KNOTS_M_S
) -> list[np.ndarray]:
    """The grids with knots at ±knots_m_s added (those inside the grid), the uniform knots too close
    to them dropped (not the end knots). An axle's two grids keep the same number of knots (the widest
    intervals of the shorter one are halved)."""
    extra = np.unique(np.concatenate([-np.asarray(knots_m_s), knots_m_s]))
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


def build_extended(
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


def tyre_coefficients(system: LinearResiduals, theta: np.ndarray) -> tuple[float, float, float]:
    """The fitted tyre's dashpot, Maxwell damping and stiffness correction (0 where the model lacks one)."""
    names = system.parameter_names

    def value(name: str) -> float:
        return float(theta[names.index(name)]) if name in names else 0.0

    return value("tyre_dashpot_Ns_per_m"), value("maxwell_damping_Ns_per_m"), value(TYRE_RATE_UNKNOWN)


def build_at(
    reference: Reference, current: FittedModel, structure: ModelStructure, values: np.ndarray
) -> tuple[LinearResiduals, EquationSignals, list[np.ndarray]]:
    """The extended system of `structure` with channel parameters `values`, its airborne samples (with
    tyre_liftoff) decided by the current model's tyre; airborne is [] without tyre_liftoff."""
    tyre = tyre_coefficients(current.system, current.theta)
    system, signals, airborne = build_extended(
        reference, structure, corrections_of(structure.channel_parameters, values), None, tyre
    )
    return system, signals, airborne if structure.has(EffectName.TYRE_LIFTOFF) else []
