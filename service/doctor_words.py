"""The model doctor's result in words, shared by `shockbench diagnose`, its Markdown report
(service.doctor_report) and the test report's doctor section (service.report.content): each named family's
fitted shape in one phrase (from the keys of estimator.doctor.parameters.report) and the goodness-of-fit
verdict with its p-value (estimator.doctor.criteria.GoodnessOfFit).

Works on the JSON form (a step's `parameters` dict), so a stored diagnosis reads as a fresh one; a stored
result of the earlier doctor, whose parameters have other keys, falls back to the plain list of values.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping

DEPARTS_FRACTION = 0.25
"""The spring curve is said to depart from linear at the innermost knot whose extra rate is at least this
fraction of the rate at static load (a reading aid only: the doctor's tests do not use it)."""
_HINGE_KEY = re.compile(r"extra_rate_beyond_([0-9.]+)_mm_(extension|compression)_N_per_m")

Parameters = Mapping[str, float | str]


JOIN = " + "
"""Between the labels of families a step named together, as the result's JSON has them
(estimator.doctor.catalog.JOIN; not imported: this module reads stored results without the estimator)."""


def micrometres(gap_m: float | None) -> str:
    """A gap (m) in words: "35.0 µm", or "diverged" where the model has none (null in stored JSON)."""
    return f"{gap_m * 1e6:.1f} µm" if gap_m is not None and math.isfinite(gap_m) else "diverged"


def family(effect: str) -> str:
    """The family of an effect label: "sensor_dynamics(x_s, lag)" -> "sensor_dynamics"."""
    return effect.split("(", 1)[0]


def plain(parameters: Parameters) -> str:
    """Every parameter as `key = value`."""
    return ", ".join(
        f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in parameters.items()
    )


def departs_from_linear(parameters: Parameters) -> list[str]:
    """Per side, where the spring curve departs from linear: "beyond 14.0 mm of compression (+3.2e+04
    N/m)" (DEPARTS_FRACTION)."""
    rate = abs(float(parameters["rate_at_static_load_N_per_m"]))
    sides: dict[str, list[tuple[float, float]]] = {}
    for key, value in parameters.items():
        match = _HINGE_KEY.fullmatch(key)
        if match:
            sides.setdefault(match.group(2), []).append((float(match.group(1)), float(value)))
    out = []
    for side in ("compression", "extension"):
        for knot_mm, extra in sorted(sides.get(side, [])):
            if abs(extra) >= DEPARTS_FRACTION * rate:
                out.append(f"beyond {knot_mm:.1f} mm of {side} ({extra:+.3g} N/m)")
                break
    return out


def _spring(p: Parameters) -> str:
    rate, stated = float(p["rate_at_static_load_N_per_m"]), float(p["stated_rate_N_per_m"])
    departs = departs_from_linear(p)
    linear = "linear over the deflection measured"
    shape = "departs from linear " + " and ".join(departs) if departs else linear
    return (
        f"rate at static load {rate:.4g} N/m (stated {stated:.4g}, {float(p['rate_change_percent']):+.1f}%); "
        f"{shape}"
    )


def _friction(p: Parameters) -> str:
    velocity_mm_s = 1e3 * float(p["stribeck_velocity_m_s"])
    if presliding_mm := 1e3 * float(p.get("presliding_m", 0.0)):
        return (
            f"hysteretic friction of {float(p['sliding_friction_N']):.3g} N sliding, built up over a "
            f"presliding displacement of {presliding_mm:.3g} mm after each reversal (Dahl)"
        )
    return (
        f"force step of {float(p['sliding_friction_N']):.3g} N sliding, static peak "
        f"{float(p['static_friction_N']):.3g} N (Stribeck velocity {velocity_mm_s:.3g} mm/s)"
    )


def _dynamics(p: Parameters) -> str:
    constant = p["lag_time_constant_s"] if "lag_time_constant_s" in p else p["averaging_window_s"]
    what = "τ" if "lag_time_constant_s" in p else "window"
    return (
        f"{p['channel']}: {p['filter']}, {what} {1e3 * float(constant):.3g} ms after a delay of "
        f"{1e3 * float(p['delay_s']):.3g} ms (reads {1e3 * float(p['equivalent_delay_s']):.3g} ms late)"
    )


def _gain(p: Parameters) -> str:
    error = float(p["gain_error_percent"])
    return f"{p['channel']} reads {abs(error):.3g}% {'high' if error >= 0 else 'low'}"


def _tyre(p: Parameters) -> str:
    return (
        f"tyre rate {float(p['tyre_stiffness_N_per_m']):.4g} N/m (stated "
        f"{float(p['stated_tyre_stiffness_N_per_m']):.4g}, {float(p['change_percent']):+.1f}%)"
    )


def _offset(p: Parameters) -> str:
    return f"{p['channel']} zero off by {1e6 * float(p['offset_m']):+.1f} µm"


SHAPES = {
    "spring_curve": _spring,
    "low_speed_friction": _friction,
    "sensor_dynamics": _dynamics,
    "sensor_gain": _gain,
    "tyre_stiffness": _tyre,
    "sensor_offset": _offset,
}


def shape(effect: str, parameters: Parameters) -> str:
    """The fitted shape of a named family in one phrase (every value, for families without one); families
    named together ("spring_curve + tyre_stiffness"): each one's phrase from their shared parameters."""
    if JOIN in effect:
        return "; ".join(shape(member, parameters) for member in effect.split(JOIN))
    words = SHAPES.get(family(effect))
    if words is None:
        return plain(parameters)
    try:
        return words(parameters)
    except (KeyError, TypeError, ValueError):  # a result of the earlier doctor: other keys
        return plain(parameters)


def fit_verdict(p_value: float | None, alpha: float | None, unexplained: bool, where: str | None) -> str:
    """The goodness-of-fit test in words: "p = 0.31: nothing left that the noise does not explain", or
    "p = 0.001 < α = 0.05: unexplained; <where>"."""
    if p_value is None or alpha is None:  # a result of the earlier doctor: no test
        return "unexplained" + (f"; {where}" if where else "") if unexplained else "explained"
    if unexplained:
        return f"p = {p_value:.2g} < α = {alpha:g}: unexplained" + (f"; {where}" if where else "")
    return f"p = {p_value:.2g}: nothing left that the noise does not explain"
