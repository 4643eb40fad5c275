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
                "stribeck_peak_N": F_s, "stribeck_velocity_m_s": v_s, "presliding_m": z,
                "spring_hinges": [{"knot_m": 0.02, "rate_N_per_m": 1e5}], "tyre_liftoff": true,
                "guide_body_friction_N": 0.1, "guide_wheel_friction_N": 0.1,
                "channel_delay_s": {"x_t": 0.002}, "sensor_offset_m": {"x_r": 1e-4},
                "sensor_lag_s": {"x_s": 0.004}, "sensor_average_s": {"x_s": 0.01},
                "sensor_gain_error": {"x_t": 0.03}}

(the forces act at every corner, as the doctor fits them, with estimator.dynamics.CornerPhysics's meaning:
the Stribeck peak and its velocity come together; a presliding displacement z makes the friction
hysteretic (Dahl); at most HINGES spring hinges; a quarter-car rig's frame guides hold its body and
wheel by a friction against the frame. A delayed channel reads
the true motion `delay` later, an offset channel reads it plus the offset, a lagging one through a
first-order lag of that time constant, an averaging one its mean over that window, one with a gain error
ε reads (1 + ε) times it: estimator.laser_channels.ChannelCorrections). An effect name this module does not
know is refused, never ignored, so a model is never simulated without part of itself.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from estimator.damper import PiecewiseLinearCurve
from estimator.dynamics import HINGES, AxlePhysics, CornerPhysics, QuarterCarPhysics
from estimator.errors import UserError
from estimator.frame_guides import GUIDE_FRICTION_NAMES
from estimator.laser_channels import ChannelCorrections
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


STRIBECK_EFFECTS = ("stribeck_peak_N", "stribeck_velocity_m_s")
"""The Stribeck friction's two numbers: given together or not at all."""
FORCE_EFFECTS = (
    "coulomb_friction_N",
    "cubic_spring_N_per_m3",
    "tyre_dashpot_Ns_per_m",
    *STRIBECK_EFFECTS,
    "presliding_m",
    *GUIDE_FRICTION_NAMES,  # a lab rig's frame guides (quarter car only)
)
"""The `effects` keys that are forces at every corner, as estimator.dynamics.CornerPhysics names them."""
CHANNEL_EFFECTS = (
    "channel_delay_s",
    "sensor_offset_m",
    "sensor_lag_s",
    "sensor_average_s",
    "sensor_gain_error",
)
CHANNEL_BOUNDS = {
    "channel_delay_s": (0.0, True, "must be >= 0 (a channel lags)"),
    "sensor_lag_s": (0.0, True, "must be >= 0 (a lag's time constant)"),
    "sensor_average_s": (0.0, True, "must be >= 0 (an averaging window)"),
    "sensor_gain_error": (-1.0, False, "must be > -1 (the channel reads (1 + ε)·x)"),
}
"""Per channel effect: the least value, whether it may equal it, and the error's words."""
EFFECT_KEYS = (*FORCE_EFFECTS, "spring_hinges", "tyre_liftoff", *CHANNEL_EFFECTS)


@dataclass(frozen=True)
class SpringHinge:
    """One hinge of the spring's correction (estimator.dynamics.CornerPhysics): rate·(ζ − knot) beyond the
    knot on its side (ζ > knot >= 0 or ζ < knot < 0)."""

    knot_m: float
    rate_N_per_m: float


@dataclass(frozen=True)
class ModelEffects:
    """The effects of a model beyond identify's form (module docstring); zero / False / empty = absent."""

    coulomb_friction_N: float = 0.0
    cubic_spring_N_per_m3: float = 0.0
    tyre_dashpot_Ns_per_m: float = 0.0
    stribeck_peak_N: float = 0.0
    stribeck_velocity_m_s: float = 0.0
    presliding_m: float = 0.0
    guide_body_friction_N: float = 0.0
    guide_wheel_friction_N: float = 0.0
    spring_hinges: tuple[SpringHinge, ...] = ()
    tyre_liftoff: bool = False
    channel_delay_s: Mapping[str, float] = field(default_factory=dict)
    sensor_offset_m: Mapping[str, float] = field(default_factory=dict)
    sensor_lag_s: Mapping[str, float] = field(default_factory=dict)
    sensor_average_s: Mapping[str, float] = field(default_factory=dict)
    sensor_gain_error: Mapping[str, float] = field(default_factory=dict)

    def _present(self, key: str) -> bool:
        if key in STRIBECK_EFFECTS:  # a peak without its velocity (or the reverse) is no Stribeck term
            return bool(self.stribeck_peak_N and self.stribeck_velocity_m_s)
        return bool(getattr(self, key))

    @property
    def names(self) -> list[str]:
        """The keys of the effects present, in EFFECT_KEYS order."""
        return [key for key in EFFECT_KEYS if self._present(key)]

    def to_json(self) -> dict[str, object]:
        """The `effects` object: only the effects present."""
        return {key: _plain(getattr(self, key)) for key in self.names}

    def corner(self, corner: CornerPhysics, static_wheel_load_N: float) -> CornerPhysics:
        """The corner with these force effects added."""
        if not any(self._present(key) for key in (*FORCE_EFFECTS, "spring_hinges", "tyre_liftoff")):
            return corner
        hinged = bool(self.spring_hinges)
        stribeck = self._present("stribeck_peak_N")
        return replace(
            corner,
            coulomb_friction_N=self.coulomb_friction_N,
            cubic_spring_N_per_m3=self.cubic_spring_N_per_m3,
            tyre_dashpot_Ns_per_m=self.tyre_dashpot_Ns_per_m,
            spring_hinge_knots_m=np.array([h.knot_m for h in self.spring_hinges]) if hinged else None,
            spring_hinge_rates_N_per_m=np.array([h.rate_N_per_m for h in self.spring_hinges])
            if hinged
            else None,
            stribeck_peak_N=self.stribeck_peak_N if stribeck else 0.0,
            stribeck_velocity_m_s=self.stribeck_velocity_m_s if stribeck else 0.0,
            presliding_m=self.presliding_m,
            guide_body_friction_N=self.guide_body_friction_N,
            guide_wheel_friction_N=self.guide_wheel_friction_N,
            tyre_liftoff=self.tyre_liftoff,
            static_wheel_load_N=static_wheel_load_N,
        )

    def channel_corrections(self) -> ChannelCorrections:
        """The channel effects as ChannelCorrections, which validate applies around the simulation
        (estimator.validation)."""
        return ChannelCorrections(
            dict(self.channel_delay_s),
            dict(self.sensor_offset_m),
            lag_s=dict(self.sensor_lag_s),
            average_s=dict(self.sensor_average_s),
            gain_error=dict(self.sensor_gain_error),
        )


def _plain(value: object) -> object:
    if isinstance(value, tuple):  # the spring hinges
        return [asdict(item) for item in value]
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


def with_curves_of(data: Mapping[str, Any], model: IdentifiedModel) -> dict[str, Any]:
    """A model's JSON (identify's form, as model_from_json reads it) with `model`'s damper curves and tyre
    damping in place of its own, the rest as it was (a model refined on a recording: estimator.validation
    .refined_on)."""
    curves = [
        {**entry, "velocity_m_s": curve.velocity_m_s.tolist(), "force_N": curve.force_N.tolist()}
        for entry, curve in zip(data["curves"], model.curves, strict=True)
    ]
    return {**data, "curves": curves, "tyre_damping_Ns_per_m": float(model.tyre_damping_Ns_per_m)}


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
    if (STRIBECK_EFFECTS[0] in data) != (STRIBECK_EFFECTS[1] in data):
        raise ModelFormatError(
            "model: 'effects.stribeck_peak_N' and 'effects.stribeck_velocity_m_s' go together (both or none)"
        )
    if values.get("stribeck_velocity_m_s", 1.0) <= 0:
        raise ModelFormatError("model: 'effects.stribeck_velocity_m_s' must be > 0")
    if values.get("presliding_m", 0.0) < 0:
        raise ModelFormatError("model: 'effects.presliding_m' must be >= 0 (0: no hysteresis)")
    guides = [key for key in GUIDE_FRICTION_NAMES if key in values]
    if guides and axle:  # (any sign, as coulomb_friction_N: a fit may leave one a little below zero)
        raise ModelFormatError(
            f"model: 'effects.{guides[0]}' is a quarter-car rig's frame guides, not an axle's"
        )
    if "spring_hinges" in data:
        values["spring_hinges"] = _spring_hinges(data["spring_hinges"])
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
        if key in CHANNEL_BOUNDS:
            least, inclusive, words = CHANNEL_BOUNDS[key]
            if any(v < least or (v == least and not inclusive) for v in values[key].values()):
                raise ModelFormatError(f"model: 'effects.{key}' {words}")
    return ModelEffects(**values)


def _spring_hinges(data: Any) -> tuple[SpringHinge, ...]:
    """The `spring_hinges` list: at most HINGES {knot_m, rate_N_per_m} objects."""
    if not isinstance(data, list) or len(data) > HINGES:
        raise ModelFormatError(
            f"model: 'effects.spring_hinges' must be a list of at most {HINGES} {{knot_m, rate_N_per_m}}"
        )
    hinges = []
    for index, hinge in enumerate(data):
        where = f"effects.spring_hinges[{index}]."
        if not isinstance(hinge, Mapping):
            raise ModelFormatError(f"model: '{where[:-1]}' must be an object {{knot_m, rate_N_per_m}}")
        unknown = sorted(set(hinge) - {"knot_m", "rate_N_per_m"})
        if unknown:
            raise ModelFormatError(
                f"model: unknown key '{where}{unknown[0]}' (a hinge has knot_m, rate_N_per_m)"
            )
        hinges.append(SpringHinge(_number(hinge, "knot_m", where), _number(hinge, "rate_N_per_m", where)))
    return tuple(hinges)


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
