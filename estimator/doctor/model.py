"""A model with effect families added, and its equations: the paper's on the recording corrected for its
channel families, with the uncorrected recording's damper grid and filters (every candidate shares its
unknowns) and the force families' columns appended; cached per Reference (a diagnosis fits many models)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from estimator.damper import PiecewiseLinearCurve, low_speed_grids
from estimator.doctor.catalog import (
    CATALOG,
    CHANNEL_PARAMETERS,
    SPRING_RATE_UNKNOWN,
    TYRE_RATE_UNKNOWN,
    EffectInstance,
    EffectName,
    EquationSignals,
    hinge_knots_m,
    hinge_unknowns,
    presliding_m,
    stribeck_velocity_m_s,
    with_columns,
)
from estimator.equations import LinearResiduals, build, damper_grids
from estimator.errors import InvalidValueError
from estimator.laser_channels import ChannelCorrections
from estimator.recording import Recording
from estimator.signals import FilterChoice
from estimator.vehicle import TyreModel, VehicleConstant, VehicleParameters

ChannelParameters = list[tuple[EffectInstance, str]]  # (family, kind) of each Gauss-Newton parameter


@dataclass(frozen=True)
class ModelStructure:
    """The families a model has beyond the vehicle file's constants, in the order they were added."""

    effects: tuple[EffectInstance, ...] = ()

    def with_effect(self, *effects: EffectInstance) -> ModelStructure:
        return replace(self, effects=(*self.effects, *effects))

    def has(self, name: EffectName) -> bool:
        return any(e.name is name for e in self.effects)

    @property
    def channel_parameters(self) -> ChannelParameters:
        return [(e, kind) for e in self.effects for kind in CHANNEL_PARAMETERS.get((e.name, e.variant), ())]

    @property
    def labels(self) -> list[str]:
        return [e.label for e in self.effects]


def starting_structure(tyre: TyreModel) -> ModelStructure:
    """The structure a `--tyre` option stands for."""
    if tyre is TyreModel.SPRING:
        return ModelStructure()
    name = EffectName.TYRE_DAMPING if tyre is TyreModel.KELVIN_VOIGT else EffectName.TYRE_VISCOELASTIC
    return ModelStructure((EffectInstance(name),))


def corrections_of(parameters: ChannelParameters, values: np.ndarray) -> ChannelCorrections:
    """The channel corrections that Gauss-Newton parameters with these values stand for."""
    tables: dict[str, dict[str, float]] = {k: {} for k in ("delay", "offset", "lag", "average", "gain")}
    for (effect, kind), value in zip(parameters, values, strict=True):
        tables[kind][str(effect.channel)] = float(value)
    return ChannelCorrections(*tables.values())


LOW_SPEED_KNOTS_M_S = (0.0, 0.01)
"""Suspension velocities (m/s) of extra knots (± each, evenly spaced): the curve follows a damper's low-speed
rise, and a friction step is what it cannot make."""


@dataclass(frozen=True)
class FitSettings:
    points: int | None = None
    """Damper curve points before the low-speed knots (None: identify's default)."""
    nsample: int | None = 5000
    low_speed_knots_m_s: tuple[float, ...] = LOW_SPEED_KNOTS_M_S
    """The low-speed knots (low_speed_grids); a bootstrap truth has them finer (estimator.doctor.expected)."""


@dataclass
class FittedModel:
    """A structure identified on a recording: θ of the extended system, the Gauss-Newton parameters
    (structure.channel_parameters' order), per corner where the tyre is off the plate (with tyre_liftoff)."""

    structure: ModelStructure
    vehicle: VehicleParameters
    theta: np.ndarray
    system: LinearResiduals
    signals: EquationSignals
    channel_values: np.ndarray
    airborne: list[np.ndarray]
    objective: float
    knots_m: tuple[float, ...]
    curve_override: tuple[PiecewiseLinearCurve, ...] | None = None
    """Damper curves to simulate instead of the fitted points (a bootstrap truth's smooth curves)."""

    def value(self, name: str) -> float:
        """The unknown `name` of θ (0 where the model lacks it)."""
        names = self.system.parameter_names
        return float(self.theta[names.index(name)]) if name in names else 0.0

    def channel_values_for(self, parameters: ChannelParameters) -> np.ndarray:
        """This model's values of `parameters`, matched by family and kind (0 where it lacks one)."""
        own = dict(zip(self.structure.channel_parameters, self.channel_values, strict=True))
        return np.array([own.get(p, 0.0) for p in parameters], dtype=float)

    def channel_value(self, effect: EffectInstance, kind: str) -> float:
        return float(self.channel_values_for([(effect, kind)])[0])

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
        system = self.system
        return tuple(
            PiecewiseLinearCurve(g, self.theta[s])
            for g, s in zip(system.grids_m_s, system.curve_slices, strict=True)
        )

    @property
    def tyre(self) -> tuple[float, float, float]:
        """The tyre's dashpot, Maxwell damping and stiffness correction (0 where the model lacks one)."""
        dashpot, maxwell = self.value("tyre_dashpot_Ns_per_m"), self.value("maxwell_damping_Ns_per_m")
        return dashpot, maxwell, self.value(TYRE_RATE_UNKNOWN)

    @property
    def corrections(self) -> ChannelCorrections:
        return corrections_of(self.structure.channel_parameters, self.channel_values)

    def residuals(self) -> np.ndarray:
        """(equations, selected samples) residual forces, N."""
        return self.system.residuals(self.theta)

    @property
    def spring_stiffness_N_per_m(self) -> float:
        """K_s at the static position: the stated rate plus spring_curve's change (if it has one)."""
        return float(self.vehicle.spring_stiffness_N_per_m or 0.0) + self.value(SPRING_RATE_UNKNOWN)

    @property
    def tyre_stiffness_N_per_m(self) -> float:
        """K_t: the stated rate plus tyre_stiffness's change (if it has one)."""
        return float(self.vehicle.tyre_stiffness_N_per_m or 0.0) + self.value(TYRE_RATE_UNKNOWN)

    @property
    def hinge_rates_N_per_m(self) -> np.ndarray:
        return np.array([self.value(n) for n in hinge_unknowns(self.knots_m)])

    @property
    def _friction(self) -> EffectInstance | None:
        """The model's low_speed_friction variant, if it has the family."""
        return next((e for e in self.structure.effects if e.name is EffectName.LOW_SPEED_FRICTION), None)

    @property
    def stribeck_velocity_m_s(self) -> float:
        """v_s of the model's low_speed_friction variant (0 without the family)."""
        return stribeck_velocity_m_s(self._friction) if self._friction else 0.0

    @property
    def presliding_m(self) -> float:
        """z of the model's hysteretic low_speed_friction (0 without it)."""
        return presliding_m(self._friction) if self._friction else 0.0

    @property
    def airborne_fraction(self) -> float:
        return float(np.mean([a.mean() for a in self.airborne])) if self.airborne else 0.0


BUILD_CACHE_ENTRIES = 8  # equation systems a Reference keeps
COLUMN_CACHE_ENTRIES = 32  # family columns a Reference keeps


@dataclass(frozen=True)
class Reference:
    """What every fit of one recording shares: the uncorrected recording's damper grids and filters, the
    hinge knots, the constants identified from it, and caches of the systems built (guarded by `lock`)."""

    recording: Recording
    vehicle: VehicleParameters
    settings: FitSettings
    grids: list[np.ndarray]
    filters: FilterChoice
    knots_m: tuple[float, ...]
    identified: frozenset[VehicleConstant] = frozenset()
    built: dict[tuple, Any] = field(default_factory=dict, compare=False, repr=False)
    columns: dict[tuple, Any] = field(default_factory=dict, compare=False, repr=False)
    lock: threading.Lock = field(default_factory=threading.Lock, compare=False, repr=False)

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
        filters, grids = damper_grids(recording, vehicle, settings.points, settings.nsample)
        knots = hinge_knots_m(recording, vehicle)
        grids = low_speed_grids(grids, settings.low_speed_knots_m_s)
        return Reference(recording, vehicle, settings, grids, filters, knots, identified)

    def on(self, recording: Recording) -> Reference:
        """The Reference of another recording (a bootstrap draw): these settings, hinge knots, constants."""
        on = Reference.of(recording, self.vehicle, self.settings, self.identified)
        return replace(on, knots_m=self.knots_m)


def _airborne(
    signals: EquationSignals, dashpot: float, maxwell: float, stiffness_change: float
) -> list[np.ndarray]:
    """Per corner, 1.0 where the fitted tyre's force would pull on the plate, else 0.0. An airborne Maxwell
    element is not driven (it relaxes), so with one the samples are decided in order."""
    vehicle, load = signals.vehicle, signals.vehicle.static_wheel_load_N
    masks = []
    for corner in signals.corners:
        force = (vehicle.tyre_stiffness_N_per_m + stiffness_change) * corner.tyre_deflection_smooth_m
        if dashpot:
            force = force + dashpot * corner.tyre_rate_m_s
        if not maxwell:
            masks.append((force > load).astype(float))
            continue
        # EquationSignals.maxwell_regressor's recursion, its input gated
        dt = signals.sample_time_s
        tau = vehicle.maxwell_time_constant_s(dt)
        pole, gain = (2.0 * tau - dt) / (2.0 * tau + dt), dt / (2.0 * tau + dt)
        rates, spring = corner.tyre_rate_m_s.tolist(), force.tolist()
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
    """cache[key], made (outside the lock) if missing; the least recently used beyond `entries` forgotten."""
    with lock:
        if key in cache:
            cache[key] = cache.pop(key)
            return cache[key]
    value = make()
    with lock:
        cache[key] = value
        while len(cache) > entries:
            del cache[next(iter(cache))]
    return value


def _base_system(
    reference: Reference, corrections: ChannelCorrections
) -> tuple[tuple, LinearResiduals, EquationSignals]:
    """The paper's system on the recording as `corrections` correct it, and its key (zero ones left out)."""
    key = tuple(
        tuple(sorted((name, value) for name, value in getattr(corrections, f.name).items() if value))
        for f in fields(corrections)
    )

    def make() -> tuple[LinearResiduals, EquationSignals]:
        recording, r, s = corrections.apply(reference.recording), reference, reference.settings
        known = (s.points, s.nsample, r.filters, r.grids)  # no tyre terms, no rig's guides: families it tests
        base = build(recording, r.vehicle, TyreModel.SPRING, *known, guides=False)
        return base, EquationSignals(recording, r.vehicle, base)

    base, signals = _cached(reference.built, reference.lock, key, make, BUILD_CACHE_ENTRIES)
    return key, base, signals


def build_extended(
    reference: Reference,
    structure: ModelStructure,
    values: np.ndarray,
    tyre: tuple[float, float, float],
    airborne: list[np.ndarray] | None = None,
) -> tuple[LinearResiduals, EquationSignals, list[np.ndarray]]:
    """The extended system of `structure` with channel parameters `values`; where the tyre is off the plate
    (tyre_liftoff; [] without) is `airborne`, else decided from `tyre` (a FittedModel.tyre)."""
    key, base, signals = _base_system(reference, corrections_of(structure.channel_parameters, values))
    liftoff = structure.has(EffectName.TYRE_LIFTOFF)
    if airborne is None and liftoff:
        airborne = _airborne(signals, *tyre)
    elif airborne is None:
        airborne = [np.zeros(signals.recording.time_s.size)] * len(signals.corners)
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
    return with_columns(base, columns, offset), signals, airborne if liftoff else []
