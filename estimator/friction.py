"""The suspension's friction laws, as the simulation (estimator.dynamics, the compiled kernel) and the model
doctor's equations (estimator.doctor.catalog) use them: Coulomb friction with a smoothed sign and a Stribeck
peak, the steepest slope of that law (how many Runge-Kutta steps it needs), and hysteretic friction by
Dahl's state, integrated in time or run along a measured deflection; a step's mean over each sample
interval, as the equations take it."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

COULOMB_SMOOTHING_M_S = 0.005
"""Coulomb friction is F_c·tanh(v / this): a smooth sign function, so the ODE stays integrable."""


def coulomb_sign(velocity_m_s: np.ndarray) -> np.ndarray:
    """The smooth sign the Coulomb friction force is F_c times: tanh(v / COULOMB_SMOOTHING_M_S) (the
    compiled kernel, estimator.simulation_kernel_numba, spells the same law out)."""
    return np.tanh(velocity_m_s / COULOMB_SMOOTHING_M_S)


INTERVAL_POINTS = 16  # points per sample interval at which interval_mean evaluates its function


def interval_mean(function: Callable[[np.ndarray], np.ndarray], series: np.ndarray) -> np.ndarray:
    """Per sample, the mean of function(series(t)) over its own interval (the series linear between samples):
    a force that steps at a zero crossing acts for its share of the interval, not a sample early or late."""
    before = np.concatenate([series[:1], series[:-1]])
    after = np.concatenate([series[1:], series[-1:]])
    total = np.zeros_like(series, dtype=float)
    for k in range(INTERVAL_POINTS):
        fraction = (k + 0.5) / INTERVAL_POINTS - 0.5
        neighbour = before if fraction < 0.0 else after
        total += function(series + (neighbour - series) * abs(fraction))
    return total / INTERVAL_POINTS


def hysteresis_rate(velocity_m_s: np.ndarray, hysteresis: np.ndarray, presliding_m: np.ndarray) -> np.ndarray:
    """ḣ of Dahl's friction state h (F = F_c·h): (v − |v|·h)/z, z the presliding displacement over which a
    reversed friction force builds up (Dahl 1968; the LuGre model's bristle without its Stribeck and
    damping terms); 0 where z is 0 (no hysteresis there)."""
    present = np.asarray(presliding_m) > 0.0
    scale = np.where(present, presliding_m, 1.0)
    return np.where(present, (velocity_m_s - np.abs(velocity_m_s) * hysteresis) / scale, 0.0)


def hysteresis_interval_mean(deflection_m: np.ndarray, presliding_m: float) -> np.ndarray:
    """Dahl's h along a measured deflection ζ (linear between samples, h = 0 at the start), per sample the
    mean over its own interval (half a sample each way). Dahl's law does not depend on the rate:
    dh/dζ = (1 − sgn(dζ)·h)/z, so over a stretch moving by Δ in one direction s, h relaxes toward s as
    s + (h − s)·e^(−|Δ|/z), and its mean over the stretch is s + (h − s)·(1 − e^(−a))/a, a = |Δ|/z:
    exact for the piecewise-linear path, whatever the sample rate."""
    zeta = np.asarray(deflection_m, dtype=float)
    half = np.empty(2 * zeta.size - 1)  # the path at samples and midpoints
    half[::2], half[1::2] = zeta, 0.5 * (zeta[1:] + zeta[:-1])
    move = np.diff(half)
    direction, a = np.sign(move), np.abs(move) / presliding_m
    decay = np.exp(-a)
    share = np.where(a > 1e-12, -np.expm1(-a) / np.maximum(a, 1e-12), 1.0)  # (1 − e^(−a))/a
    start = np.empty(move.size)  # h at the start of each half-sample stretch
    h = 0.0
    for k, (d, e) in enumerate(zip(direction.tolist(), decay.tolist(), strict=True)):
        start[k] = h
        h = d + (h - d) * e
    means = direction + (start - direction) * share
    edges = np.concatenate([[0.0], means, [0.0]])  # the first and last samples have one half inside
    weights = np.concatenate([[0.0], np.ones(means.size), [0.0]])
    total, count = edges[0::2] + edges[1::2], weights[0::2] + weights[1::2]
    return total / np.maximum(count, 1.0)


FRICTION_SLOPE_GRID = 801
"""Velocities friction_slope_Ns_per_m looks at from 0 to 4 times the wider of the band and v_s: a step of a
200th of the wider scale, where the peak's slope changes by well under a percent; the smoothed step is
steepest at v = 0, which is on the grid (tests/estimator/test_force_shapes.py: within 1% of a fine grid)."""


def friction_slope_Ns_per_m(
    coulomb_friction_N: float | np.ndarray,
    stribeck_peak_N: float | np.ndarray = 0.0,
    stribeck_velocity_m_s: float | np.ndarray = 0.0,
) -> float:
    """The steepest slope |dF/dv| of the friction law F(v) = (F_c + peak·exp(−(v/v_s)²))·s(v)
    (CornerPhysics.suspension_force_N; s the smoothed sign, coulomb_sign), over velocity and over the
    columns of arrays: at zero velocity (F_c + peak)/COULOMB_SMOOTHING_M_S, elsewhere where the peak's decay
    bends it. A zero v_s is no Stribeck term. Why not (|F_c| + |peak|)/band: a fitted friction often has a
    peak of the other sign (+1 550 N sliding with a −1 420 N peak at 20 mm/s is a smooth 130 → 1 550 N
    rise), whose steepest slope is 61 kN·s/m, not the 594 kN·s/m that sum gave: 48 Runge-Kutta steps a 2 ms
    sample instead of 6 on a motorcycle's corner."""
    coulomb, peak, v_s = np.broadcast_arrays(
        *(
            np.atleast_1d(np.asarray(x, dtype=float))
            for x in (coulomb_friction_N, stribeck_peak_N, stribeck_velocity_m_s)
        )
    )
    peak = np.where(v_s > 0.0, peak, 0.0)
    v_s = np.where(v_s > 0.0, v_s, COULOMB_SMOOTHING_M_S)
    band = COULOMB_SMOOTHING_M_S
    # F is odd: v >= 0 suffices; 4 times the wider scale is where both the step and the peak have settled
    scale = np.maximum(band, v_s)
    velocity = np.linspace(0.0, 1.0, FRICTION_SLOPE_GRID)[:, None] * 4.0 * scale
    decay = np.exp(-np.square(velocity / v_s))
    step = np.tanh(velocity / band)
    rise = (coulomb + peak * decay) * (1.0 - step * step) / band  # the smoothed sign's step
    bend = step * peak * decay * 2.0 * velocity / v_s**2  # the peak's decay away from zero
    return float(np.max(np.abs(rise - bend)))


def friction_force_N(
    velocity_m_s: np.ndarray, coulomb_friction_N: float, stribeck_peak_N: float, stribeck_velocity_m_s: float
) -> np.ndarray:
    """The friction law F(v) = (F_c + peak·exp(−(v/v_s)²))·s(v), s the smoothed sign (coulomb_sign), v_s > 0:
    what CornerPhysics.suspension_force_N and the compiled kernel add for a strut's sliding friction with
    a Stribeck peak (they also carry Dahl's hysteretic sign, which this leaves out)."""
    decay = np.exp(-np.square(velocity_m_s / stribeck_velocity_m_s))
    return (coulomb_friction_N + stribeck_peak_N * decay) * coulomb_sign(velocity_m_s)


def friction_peak_N(coulomb_friction_N: float, stribeck_peak_N: float, stribeck_velocity_m_s: float) -> float:
    """The largest force |F(v)| of the friction law F(v) = (F_c + peak·exp(−(v/v_s)²))·s(v), s the smoothed
    sign (coulomb_sign): the breakaway force the law holds, what a report calls static friction. It is
    F_c + peak only where the peak outlasts the sign's smoothing (v_s well above COULOMB_SMOOTHING_M_S);
    a peak far narrower than the smoothing reaches only about 0.43·v_s/band of its height, so a fitted
    peak there stands for a step sharper than the law's, and its parameter is no force the strut holds.
    At least |F_c|, the law's limit at speed; a zero v_s is no Stribeck term. The velocities looked at
    (FRICTION_SLOPE_GRID of them) run geometrically from a hundredth of the narrower scale to 4 times the
    wider, where both have settled."""
    coulomb = float(coulomb_friction_N)
    if stribeck_velocity_m_s <= 0.0 or stribeck_peak_N == 0.0:
        return abs(coulomb)
    narrow = min(COULOMB_SMOOTHING_M_S, stribeck_velocity_m_s)
    wide = max(COULOMB_SMOOTHING_M_S, stribeck_velocity_m_s)
    velocity = np.geomspace(narrow / 100.0, 4.0 * wide, FRICTION_SLOPE_GRID)
    law = friction_force_N(velocity, coulomb, stribeck_peak_N, stribeck_velocity_m_s)
    return float(max(np.max(np.abs(law)), abs(coulomb)))
