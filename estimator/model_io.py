"""An identified model from its JSON form (the output of `shockbench identify --json`, or an object holding
those keys under `model`) back into the objects the output-error simulation runs
(estimator.output_error.IdentifiedModel). Pure: a dict in, a model out, no file I/O.

The tyre's Maxwell element is rebuilt from its relaxation time τ (`tyre_relaxation_time_s`), which does not
depend on the sample time; when only ϑ is given it is taken as referred to 1 ms, as identify prints it. So a
model identified at one sample rate simulates a recording made at another.

An axle model needs its track (m): it fixes how the identified roll inertia turns into the left and right
body motion. `track_m` is read from the dict, or given by the caller when the dict does not hold it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from estimator.damper import PiecewiseLinearCurve
from estimator.output_error import IdentifiedModel
from estimator.vehicle import (
    REFERENCE_SAMPLE_TIME_S,
    ModelKind,
    TyreModel,
    VehicleParameters,
    relaxation_time_from_coefficient,
)


class ModelFormatError(ValueError):
    """The model dict lacks a key or holds a value the model cannot be built from (one line, names it)."""


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


def model_from_json(result: Mapping[str, Any], track_m: float | None = None) -> IdentifiedModel:
    """The model of an identify result (or of its keys under `model`): one curve = quarter car, two (left,
    right) = axle. Raises ModelFormatError naming the missing or bad key."""
    if isinstance(result, Mapping) and "curves" not in result and isinstance(result.get("model"), Mapping):
        result = result["model"]  # a wrapper holding the model's keys under `model`
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
        if result.get("track_m") is not None:
            track_m = _number(result, "track_m")
        if track_m is None:
            raise ModelFormatError(
                "model: an axle model needs 'track_m' (identify's output does not hold it: give the track)"
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
    return IdentifiedModel(vehicle, tyre_model, curves, sprung, tyre_damping, roll_inertia)


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
