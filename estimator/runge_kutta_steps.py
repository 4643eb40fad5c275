"""How many Runge-Kutta steps a sample a model's simulation takes (estimator.dynamics's equations, the
compiled kernel's too): enough that the fastest decay the model has (its steepest damper segment, friction
near zero velocity, a tyre dashpot, a rig's frame guides, a Dahl state) stays within RK4's stable step, and
the plate drive interpolated to those steps. A model that would need more than MAX_SUBSTEPS counts as
diverged."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from estimator.friction import friction_slope_Ns_per_m

RK4_STABLE_STEP = 2.0
"""Largest |λ|·step the Runge-Kutta is run at for the fastest decay a model has (RK4's real-axis limit is
2.79). Measured on a motorcycle whose identified curve has a 41 kN·s/m segment near zero velocity (λ 3170/s):
the same model's gap on the same sweep was 896 µm at one step per 1 ms sample and 1879 µm at one step per
2 ms sample, against 951-953 µm at every step of 0.5 ms or less; with steps of |λ|·step ≤ 2 it is 951 µm at
both sample rates."""
MAX_SUBSTEPS = 256
"""Runge-Kutta steps per sample beyond which a model counts as diverged, unsimulated: |λ|·dt above 500, a
damper segment of 10⁶ N·s/m on a motorcycle's wheel at 1 ms (real dampers stay below 10⁵). A degenerate
fit (a body of 0.6 kg under a 3·10⁸ N·s/m segment) would otherwise ask for 10⁵ steps a sample: 27 GiB of
plate drive for a 12 s recording."""


def decay_rate_per_s(
    damper_slope_Ns_per_m: float,
    coulomb_friction_N: float | np.ndarray,
    wheel_dashpot_Ns_per_m: float,
    sprung_kg: float,
    unsprung_kg: float,
    stribeck_peak_N: float | np.ndarray = 0.0,
    stribeck_velocity_m_s: float | np.ndarray = 0.0,
    guide_friction_N: tuple[float | np.ndarray, float | np.ndarray] = (0.0, 0.0),
) -> float:
    """The fastest decay (1/s) a corner's dashpot-like forces give: the damper's steepest segment and the
    smoothed friction's (friction_slope_Ns_per_m) act between the body's share `sprung_kg` and the wheel, a
    tyre dashpot on the wheel alone, the frame guides' smoothed friction (body, wheel) on each mass alone."""
    friction = friction_slope_Ns_per_m(coulomb_friction_N, stribeck_peak_N, stribeck_velocity_m_s)
    between = damper_slope_Ns_per_m + friction
    body_guide, wheel_guide = (friction_slope_Ns_per_m(f) for f in guide_friction_N)
    return max(
        between * (1.0 / sprung_kg + 1.0 / unsprung_kg),
        (wheel_dashpot_Ns_per_m + wheel_guide) / unsprung_kg,
        body_guide / sprung_kg,
    )


def runge_kutta_substeps(decay_rate_per_s: float, sample_time_s: float) -> int:
    """Runge-Kutta steps per sample so that |λ|·step ≤ RK4_STABLE_STEP (at least one)."""
    return max(1, int(np.ceil(decay_rate_per_s * sample_time_s / RK4_STABLE_STEP)))


def steepest_slope_Ns_per_m(velocity_m_s: np.ndarray, force_N: np.ndarray) -> float:
    """The largest segment slope of piecewise-linear curve(s): force (knots,) or (knots, columns)."""
    force = np.asarray(force_N, dtype=float)
    steps = np.diff(np.asarray(velocity_m_s, dtype=float))
    slopes = np.diff(force, axis=0) / (steps[:, None] if force.ndim == 2 else steps)
    return float(np.max(slopes)) if slopes.size else 0.0


class KnotCurve(Protocol):
    """A piecewise-linear damper curve, or a population of them: knots and the forces there."""

    velocity_m_s: np.ndarray
    force_N: np.ndarray


def model_substeps(
    curves: Sequence[KnotCurve],
    sprung_mass_kg: float,
    unsprung_mass_kg: float,
    corners: int,
    sample_time_s: float,
    coulomb_friction_N: float | np.ndarray = 0.0,
    wheel_dashpot_Ns_per_m: float = 0.0,
    stribeck_peak_N: float | np.ndarray = 0.0,
    stribeck_velocity_m_s: float | np.ndarray = 0.0,
    hysteresis_rate_per_s: float = 0.0,
    guide_friction_N: tuple[float | np.ndarray, float | np.ndarray] = (0.0, 0.0),
) -> int:
    """Runge-Kutta steps per sample for a model's fastest decay: the steepest segment of its curves (of
    every column of a population), its friction (Coulomb and Stribeck peak), its tyre dashpot, the body
    shared among `corners`; friction as arrays: one per column (and corner), the steepest counts.
    hysteresis_rate_per_s: the fastest decay of a hysteretic friction's Dahl state, |v|/z at the largest
    suspension velocity expected (hysteresis_rate). guide_friction_N: the frame guides' (body, wheel)."""
    slope = max(steepest_slope_Ns_per_m(c.velocity_m_s, c.force_N) for c in curves)
    rate = decay_rate_per_s(
        slope,
        coulomb_friction_N,
        wheel_dashpot_Ns_per_m,
        sprung_mass_kg / corners,
        unsprung_mass_kg,
        stribeck_peak_N,
        stribeck_velocity_m_s,
        guide_friction_N,
    )
    return runge_kutta_substeps(max(rate, hysteresis_rate_per_s), sample_time_s)


def sample_substeps(samples: np.ndarray, steps: int) -> np.ndarray:
    """samples (time along the last axis) linearly interpolated to `steps` points per sample interval: the
    plate drive of a simulation run at `steps` Runge-Kutta steps per sample."""
    if steps == 1:
        return samples
    count = samples.shape[-1]
    position = np.arange((count - 1) * steps + 1) / steps
    index = np.minimum(position.astype(int), count - 2)
    fraction = position - index
    return samples[..., index] + fraction * (samples[..., index + 1] - samples[..., index])
