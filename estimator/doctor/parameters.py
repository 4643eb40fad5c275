"""A fitted family as the user reads it (report: SI units in the names) and whether its fitted values are
physically possible (implausible: signs and limits of physics, not thresholds)."""

from __future__ import annotations

import math

import numpy as np

from estimator.distributions import chi_square_survival
from estimator.doctor.catalog import (
    FRICTION_UNKNOWNS,
    GUIDE_FRICTION_NAMES,
    SPRING_RATE_UNKNOWN,
    TYRE_RATE_UNKNOWN,
    EffectInstance,
    EffectName,
    hinge,
    hinge_unknowns,
)
from estimator.doctor.criteria import ALPHA
from estimator.doctor.model import FittedModel
from estimator.friction import friction_peak_N
from estimator.uncertainty import confidence_intervals


def spring_curve_points(model: FittedModel) -> tuple[np.ndarray, np.ndarray]:
    """The model's suspension spring force (N) at its hinge knots and beyond (m of deflection): the stated
    rate, its change and the hinges (what the report plots)."""
    knots = np.array(model.knots_m)
    span = 1.5 * float(np.max(np.abs(knots))) / 0.7 if knots.size else 0.01
    deflection = np.unique(np.concatenate([[-span, 0.0, span], knots]))
    force = model.spring_stiffness_N_per_m * deflection
    for knot, rate in zip(knots, model.hinge_rates_N_per_m, strict=True):
        force = force + rate * hinge(deflection, knot)
    return deflection, force


def report(effect: EffectInstance, model: FittedModel) -> dict[str, float | str]:
    """The fitted parameters of one family as shown to the user."""
    name = effect.name
    if name is EffectName.SPRING_CURVE:
        stated = float(model.vehicle.spring_stiffness_N_per_m or 0.0)
        out: dict[str, float | str] = {
            "rate_at_static_load_N_per_m": model.spring_stiffness_N_per_m,
            "stated_rate_N_per_m": stated,
            "rate_change_percent": 100.0 * model.value(SPRING_RATE_UNKNOWN) / stated if stated else 0.0,
        }
        for knot, rate in zip(model.knots_m, model.hinge_rates_N_per_m, strict=True):
            side = "extension" if knot > 0 else "compression"
            out[f"extra_rate_beyond_{abs(knot) * 1e3:.1f}_mm_{side}_N_per_m"] = float(rate)
        return out
    if name is EffectName.LOW_SPEED_FRICTION:
        sliding, excess = (model.value(n) for n in FRICTION_UNKNOWNS)
        velocity = model.stribeck_velocity_m_s
        return {
            "sliding_friction_N": sliding,
            # the breakaway force the fitted law holds, not its peak parameter
            "static_friction_N": friction_peak_N(sliding, excess, velocity) if velocity else sliding + excess,
            "stribeck_velocity_m_s": velocity,
            "presliding_m": model.presliding_m,
        }
    if name is EffectName.TYRE_STIFFNESS:
        stated = float(model.vehicle.tyre_stiffness_N_per_m or 0.0)
        change = model.value(TYRE_RATE_UNKNOWN)
        return {
            "tyre_stiffness_N_per_m": stated + change,
            "stated_tyre_stiffness_N_per_m": stated,
            "change_percent": 100.0 * change / stated if stated else 0.0,
        }
    if name is EffectName.TYRE_DAMPING:
        return {"tyre_dashpot_Ns_per_m": model.value("tyre_dashpot_Ns_per_m")}
    if name is EffectName.TYRE_VISCOELASTIC:
        return {
            "tyre_damping_Ns_per_m": model.value("maxwell_damping_Ns_per_m"),
            "relaxation_time_s": model.vehicle.maxwell_time_constant_s(model.signals.sample_time_s),
        }
    if name is EffectName.TYRE_LIFTOFF:
        return {
            "static_wheel_load_N": model.vehicle.static_wheel_load_N,
            "airborne_fraction": model.airborne_fraction,
        }
    if name is EffectName.ANTI_ROLL_BAR:
        return {"anti_roll_bar_stiffness_N_per_m": model.value("anti_roll_bar_N_per_m")}
    if name is EffectName.GUIDE_FRICTION:
        return {key: model.value(key) for key in GUIDE_FRICTION_NAMES}  # the model file's keys
    channel = str(effect.channel)
    if name is EffectName.SENSOR_DYNAMICS:
        kind = str(effect.variant)
        delay, filter_s = model.channel_value(effect, "delay"), model.channel_value(effect, kind)
        equivalent = delay + (filter_s if kind == "lag" else 0.5 * filter_s)
        return {
            "channel": channel,
            "filter": "first-order lag" if kind == "lag" else "moving average",
            "delay_s": delay,
            ("lag_time_constant_s" if kind == "lag" else "averaging_window_s"): filter_s,
            "equivalent_delay_s": equivalent,
        }
    if name is EffectName.SENSOR_GAIN:
        return {"channel": channel, "gain_error_percent": 100.0 * model.channel_value(effect, "gain")}
    return {"channel": channel, "offset_m": model.channel_value(effect, "offset")}


def implausible(effect: EffectInstance, model: FittedModel) -> str | None:
    """Why the fitted family cannot be what it says (None if it can)."""
    name = effect.name
    if name is EffectName.LOW_SPEED_FRICTION:
        sliding, excess = (model.value(n) for n in FRICTION_UNKNOWNS)
        static = sliding + excess
        if sliding < 0.0 or static < 0.0:
            return f"the friction would feed energy in (sliding {sliding:.0f} N, static {static:.0f} N)"
        if excess < 0.0 and _below_zero(model, [({FRICTION_UNKNOWNS[1]: 1.0}, 0.0)]):
            # Stribeck's law falls from the breakaway level to the sliding one; a law that rises is a damper's
            return f"the force would rise with velocity (static {static:.0f} N < sliding {sliding:.0f} N)"
    elif name is EffectName.GUIDE_FRICTION:
        if _below_zero(model, [({n: 1.0}, 0.0) for n in GUIDE_FRICTION_NAMES]):
            return "a guide's friction would feed energy in"
    elif name is EffectName.TYRE_DAMPING and model.value("tyre_dashpot_Ns_per_m") < 0.0:
        return "the tyre dashpot would feed energy in"
    elif name is EffectName.ANTI_ROLL_BAR and model.value("anti_roll_bar_N_per_m") < 0.0:
        return "the bar's stiffness is negative"
    elif name is EffectName.TYRE_STIFFNESS and model.tyre_stiffness_N_per_m <= 0.0:
        return "the tyre rate is not positive"
    elif name is EffectName.SPRING_CURVE and _below_zero(model, _falling_segments(model)):
        return "the spring curve falls beyond chance somewhere: the spring would push the wrong way there"
    elif name is EffectName.TYRE_LIFTOFF and model.airborne_fraction <= 0.0:
        return "the tyre never leaves the plate in the fitted model"
    return None


def _falling_segments(model: FittedModel) -> list[tuple[dict[str, float], float]]:
    """The spring curve's segments whose fitted rate is not positive, each as (weights, stated rate): its rate
    is the stated one plus the rate change and the hinges passed on its side (catalog.hinge)."""
    stated, names = float(model.vehicle.spring_stiffness_N_per_m or 0.0), hinge_unknowns(model.knots_m)
    by_distance = sorted(zip(model.knots_m, names, strict=True), key=lambda knot: abs(knot[0]))
    change = {SPRING_RATE_UNKNOWN: 1.0}
    segments = [change]
    for side in (-1.0, 1.0):
        passed = [name for knot, name in by_distance if knot * side > 0]
        segments += [change | dict.fromkeys(passed[: j + 1], 1.0) for j in range(len(passed))]
    return [(w, stated) for w in segments if stated + sum(model.value(n) for n in w) <= 0.0]


def _below_zero(model: FittedModel, combinations: list[tuple[dict[str, float], float]]) -> bool:
    """Is any (weights, constant) + Σ weight·θ[name] below zero beyond chance: a one-sided Wald test at level
    ALPHA each (the equations' sandwich covariance, computed once). An estimate at a bound (a Coulomb
    friction's Stribeck excess, a spring curve's flat end: 0) falls below it half the time; only one that
    falls significantly contradicts the family's law."""
    if not combinations:
        return False
    covariance = confidence_intervals(model.system, model.theta, model.signals.sample_time_s).covariance
    for weights, constant in combinations:
        row = np.array([weights.get(n, 0.0) for n in model.system.parameter_names])
        value = constant + float(row @ model.theta)
        spread = math.sqrt(max(float(row @ covariance @ row), 0.0))
        if value < 0.0 and (spread == 0.0 or chi_square_survival((value / spread) ** 2, 1) < 2.0 * ALPHA):
            return True
    return False
