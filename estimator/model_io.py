"""An identified model from its JSON form (the output of `shockbench identify --json`, or an object holding
those keys under `model`) back into the objects the output-error simulation runs
(estimator.output_error.IdentifiedModel). Pure: a dict in, a model out, no file I/O.

The tyre's Maxwell element is rebuilt from its relaxation time τ (`tyre_relaxation_time_s`), which does not
depend on the sample time; when only ϑ is given it is taken as referred to 1 ms, as identify prints it. So a
model identified at one sample rate simulates a recording made at another.

An axle model needs its track (m): it fixes how the identified roll inertia turns into the left and right
body motion. identify's JSON states `track_m`; a track given by the caller overrides it (and stands in for
it in result files written before identify stated it).

Effects beyond identify's model. The `model` that `diagnose --json` prints is the final model of the
doctor, which may hold effects identify's form has no key for. They are carried under `effects` (absent or
empty: none) and simulated by estimator.validation, nothing left out:

    "effects": {"coulomb_friction_N": F_c, "cubic_spring_N_per_m3": k3, "tyre_dashpot_Ns_per_m": c,
                "tyre_liftoff": true, "channel_delay_s": {"x_t": 0.002}, "sensor_offset_m": {"x_r": 1e-4}}

(the forces act at every corner, as the doctor fits them; a delayed channel reads the true motion
`delay` later, an offset channel reads it plus the offset). An effect name this module does not know is
refused, never ignored, so a model is never simulated without part of itself.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from estimator.damper import PiecewiseLinearCurve
from estimator.dynamics import AxlePhysics, CornerPhysics, QuarterCarPhysics
from estimator.errors import UserError
from estimator.output_error import IdentifiedModel
from estimator.recording import AXLE_CHANNELS, QUARTER_CAR_CHANNELS
from estimator.vehicle import (
    REFERENCE_SAMPLE_TIME_S,
    ModelKind,
    TyreModel,
    VehicleParameters,
    relaxation_time_from_coefficient,
)


class ModelFormatError(UserError, ValueError):
    """The model dict lacks a key or holds a value the model cannot be built from (one line, names it)."""


FORCE_EFFECTS = ("coulomb_friction_N", "cubic_spring_N_per_m3", "tyre_dashpot_Ns_per_m")
"""The `effects` keys that are forces at every corner, as estimator.dynamics.CornerPhysics names them."""
CHANNEL_EFFECTS = ("channel_delay_s", "sensor_offset_m")
EFFECT_KEYS = (*FORCE_EFFECTS, "tyre_liftoff", *CHANNEL_EFFECTS)


@dataclass(frozen=True)
class ModelEffects:
    """The effects of a model beyond identify's form (module docstring); zero / False / empty = absent."""

    coulomb_friction_N: float = 0.0
    cubic_spring_N_per_m3: float = 0.0
    tyre_dashpot_Ns_per_m: float = 0.0
    tyre_liftoff: bool = False
    channel_delay_s: Mapping[str, float] = field(default_factory=dict)
    sensor_offset_m: Mapping[str, float] = field(default_factory=dict)

    @property
    def names(self) -> list[str]:
        """The keys of the effects present, in EFFECT_KEYS order."""
        return [key for key in EFFECT_KEYS if getattr(self, key)]

    def to_json(self) -> dict[str, object]:
        """The `effects` object: only the effects present."""
        return {key: _plain(getattr(self, key)) for key in self.names}

    def corner(self, corner: CornerPhysics, static_wheel_load_N: float) -> CornerPhysics:
        """The corner with these force effects added."""
        if not any(getattr(self, key) for key in (*FORCE_EFFECTS, "tyre_liftoff")):
            return corner
        return replace(
            corner,
            coulomb_friction_N=self.coulomb_friction_N,
            cubic_spring_N_per_m3=self.cubic_spring_N_per_m3,
            tyre_dashpot_Ns_per_m=self.tyre_dashpot_Ns_per_m,
            tyre_liftoff=self.tyre_liftoff,
            static_wheel_load_N=static_wheel_load_N,
        )


def _plain(value: object) -> object:
    return dict(value) if isinstance(value, Mapping) else value


@dataclass(frozen=True)
class ModelWithEffects(IdentifiedModel):
    """An identified model plus the effects of ModelEffects: its physics carries the force effects (so
    whatever simulates IdentifiedModel.physics() simulates them); the channel effects are applied by
    estimator.validation around the simulation."""

    effects: ModelEffects = field(default_factory=ModelEffects)

    def physics(self, curves: tuple[object, ...] | None = None):
        physics = super().physics(curves)
        load = self.vehicle.static_wheel_load_N
        if isinstance(physics, QuarterCarPhysics):
            return replace(physics, corner=self.effects.corner(physics.corner, load))
        assert isinstance(physics, AxlePhysics)
        left, right = (self.effects.corner(c, load) for c in (physics.left, physics.right))
        return replace(physics, left=left, right=right)


def _get(data: Mapping[str, Any], key: str, where: str = "") -> Any:
    if not isinstance(data, Mapping):
        raise ModelFormatError(f"model: {where or 'the model'} must be an object")
    if key not in data or data[key] is None:
        raise ModelFormatError(f"model: missing key '{where}{key}'")
    return data[key]


def _number(data: Mapping[str, Any], key: str, where: str = "") -> float:
    value = _get(data, key, where)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ModelFormatError(f"model: '{where}{key}' must be a finite number, got {value!r}")
    return float(value)


def _curve(data: Any, index: int) -> PiecewiseLinearCurve:
    where = f"curves[{index}]."
    points = []
    for key in ("velocity_m_s", "force_N"):
        values = _get(data, key, where)
        try:
            array = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            raise ModelFormatError(f"model: '{where}{key}' must be a list of numbers") from None
        if array.ndim != 1 or array.size < 2 or not np.all(np.isfinite(array)):
            raise ModelFormatError(f"model: '{where}{key}' must be a list of at least 2 finite numbers")
        points.append(array)
    velocity, force = points
    if velocity.size != force.size:
        raise ModelFormatError(f"model: '{where}velocity_m_s' and 'force_N' differ in length")
    if np.any(np.diff(velocity) <= 0):
        raise ModelFormatError(f"model: '{where}velocity_m_s' must increase")
    return PiecewiseLinearCurve(velocity, force)


def model_from_json(result: Mapping[str, Any], track_m: float | None = None) -> ModelWithEffects:
    """The model of an identify result, or of the `model` of a diagnose result (any object holding the
    model's keys under `model`): one curve = quarter car, two (left, right) = axle; track_m, when given,
    overrides the file's. Raises ModelFormatError naming the missing or bad key."""
    if isinstance(result, Mapping) and "curves" not in result and "model" in result:
        result = result["model"]  # a wrapper holding the model's keys under `model` (diagnose --json)
        if not isinstance(result, Mapping):
            raise ModelFormatError("model: 'model' must be an object (the diagnosis holds no final model)")
    curves_json = _get(result, "curves")
    if not isinstance(curves_json, list) or len(curves_json) not in (1, 2):
        raise ModelFormatError("model: 'curves' must hold one curve (quarter car) or two (axle: left, right)")
    curves = tuple(_curve(c, i) for i, c in enumerate(curves_json))
    axle = len(curves) == 2
    masses = _get(result, "masses_kg")
    sprung, unsprung = _number(masses, "sprung", "masses_kg."), _number(masses, "unsprung", "masses_kg.")
    stiffness = _get(result, "stiffness_N_per_m")
    spring = _number(stiffness, "spring", "stiffness_N_per_m.")
    tyre_stiffness = _number(stiffness, "tyre", "stiffness_N_per_m.")
    try:
        tyre_model = TyreModel(_get(result, "tyre_model"))
    except ValueError:
        choices = ", ".join(t.value for t in TyreModel)
        raise ModelFormatError(f"model: 'tyre_model' must be one of {choices}") from None
    tyre_damping = _number(result, "tyre_damping_Ns_per_m")
    roll_inertia = bar = None
    if axle:
        roll_inertia = _number(result, "roll_inertia_kg_m2")
        bar = _number(stiffness, "anti_roll_bar", "stiffness_N_per_m.")
        if track_m is None and result.get("track_m") is not None:
            track_m = _number(result, "track_m")
        if track_m is None:
            raise ModelFormatError(
                "model: an axle model needs 'track_m' (results of identify before it stated the track "
                "lack it: give the track, --track-m)"
            )
    try:
        vehicle = VehicleParameters(
            ModelKind.AXLE if axle else ModelKind.QUARTER_CAR,
            sprung + (2 if axle else 1) * unsprung,
            spring,
            tyre_stiffness,
            track_m=track_m if axle else None,
            anti_roll_bar_stiffness_N_per_m=bar or 0.0,
        )
        if tyre_model is TyreModel.MAXWELL:
            vehicle = vehicle.with_relaxation_time(_relaxation_time_s(result))
    except ModelFormatError:
        raise
    except ValueError as exc:
        raise ModelFormatError(f"model: {exc}") from None
    effects = _effects(result.get("effects"), axle)
    return ModelWithEffects(vehicle, tyre_model, curves, sprung, tyre_damping, roll_inertia, effects)


def _effects(data: Any, axle: bool) -> ModelEffects:
    """The `effects` object (module docstring); none when absent."""
    if data is None:
        return ModelEffects()
    if not isinstance(data, Mapping):
        raise ModelFormatError("model: 'effects' must be an object")
    unknown = sorted(set(data) - set(EFFECT_KEYS))
    if unknown:
        raise ModelFormatError(
            f"model: unknown effect 'effects.{unknown[0]}' (validate simulates {', '.join(EFFECT_KEYS)})"
        )
    values: dict[str, Any] = {key: _number(data, key, "effects.") for key in FORCE_EFFECTS if key in data}
    if "tyre_liftoff" in data:
        if not isinstance(data["tyre_liftoff"], bool):
            raise ModelFormatError("model: 'effects.tyre_liftoff' must be true or false")
        values["tyre_liftoff"] = data["tyre_liftoff"]
    channels = AXLE_CHANNELS if axle else QUARTER_CAR_CHANNELS
    for key in CHANNEL_EFFECTS:
        if key not in data:
            continue
        table = data[key]
        if not isinstance(table, Mapping):
            raise ModelFormatError(f"model: 'effects.{key}' must be an object: channel -> value")
        for channel in table:
            if channel not in channels:
                raise ModelFormatError(
                    f"model: 'effects.{key}' names channel {channel!r}; the model's are {', '.join(channels)}"
                )
        values[key] = {channel: _number(table, channel, f"effects.{key}.") for channel in table}
        if key == "channel_delay_s" and any(v < 0 for v in values[key].values()):
            raise ModelFormatError("model: 'effects.channel_delay_s' must be >= 0 (a channel lags)")
    return ModelEffects(**values)


def _relaxation_time_s(result: Mapping[str, Any]) -> float:
    """τ of the Maxwell element: stated, or from ϑ referred to 1 ms."""
    if result.get("tyre_relaxation_time_s") is not None:
        tau = _number(result, "tyre_relaxation_time_s")
    elif result.get("tyre_viscoelastic_coefficient") is not None:
        theta = _number(result, "tyre_viscoelastic_coefficient")
        if not 0.0 < theta < 1.0:
            raise ModelFormatError("model: 'tyre_viscoelastic_coefficient' must lie in (0, 1)")
        tau = relaxation_time_from_coefficient(theta, REFERENCE_SAMPLE_TIME_S)
    else:
        raise ModelFormatError("model: a maxwell tyre needs 'tyre_relaxation_time_s'")
    if not tau > 0:
        raise ModelFormatError(f"model: 'tyre_relaxation_time_s' must be > 0, got {tau}")
    return tau
