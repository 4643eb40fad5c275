"""The gap a model without missing effects reaches on this sweep: a parametric bootstrap.

A fitted model is turned into a plausible truth: its damper curve made smooth (a monotone cubic through the
identified points, linear beyond them, as a real damper is smooth and as the simulator treats tables), the
rest as fitted. That truth is driven by the measured plate; its predicted readings plus white noise of the
measured noise level make a synthetic recording, which is identified with the same model structure and
simulated again. The gap of that re-identified model against the synthetic recording contains everything a
complete model still shows (sensor noise, the piecewise-linear curve's discretisation, identification
errors) and nothing a missing effect adds.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.interpolate import PchipInterpolator

from estimator.damper import PiecewiseLinearCurve
from estimator.doctor.model import FitSettings, FittedModel, Reference, fit
from estimator.recording import Recording

SMOOTH_POINTS = 240
"""Knots of the dense table that represents the smooth truth's damper curve."""


def smooth_curve(curve: PiecewiseLinearCurve) -> PiecewiseLinearCurve:
    """A monotone cubic (PCHIP) through the curve's points, linear beyond them with the end slopes,
    tabulated densely over three times the curve's velocity span."""
    lo, hi = float(curve.velocity_m_s[0]), float(curve.velocity_m_s[-1])
    span = hi - lo
    interpolator = PchipInterpolator(curve.velocity_m_s, curve.force_N, extrapolate=False)
    slope = interpolator.derivative()
    inside = np.linspace(lo, hi, SMOOTH_POINTS)
    outside = np.array([lo - span, hi + span])
    grid = np.concatenate([outside[:1], inside, outside[1:]])
    force = np.concatenate(
        [
            [float(interpolator(lo)) - float(slope(lo)) * span],
            interpolator(inside),
            [float(interpolator(hi)) + float(slope(hi)) * span],
        ]
    )
    return PiecewiseLinearCurve(grid, force)


def smooth_truth(model: FittedModel) -> FittedModel:
    """A plausible truth for `model`: the fitted model with its damper curves made smooth."""
    return replace(model, curve_override=tuple(smooth_curve(c) for c in model.curves))


def synthetic_recording(
    recording: Recording, predicted: dict[str, np.ndarray], noise_m: float, seed: int
) -> Recording:
    """Predicted body and wheel readings with white noise of noise_m added; the plate as measured."""
    rng = np.random.default_rng(seed)
    channels = dict(recording.channels)
    for name, x in predicted.items():
        channels[name] = x + rng.normal(0.0, noise_m, size=x.size)
    return Recording(recording.time_s, channels, {"source": "model doctor: expected gap"})


def refit_on(synthetic: Recording, model: FittedModel, settings: FitSettings) -> FittedModel:
    """The model's structure identified on the synthetic recording."""
    return fit(Reference.of(synthetic, model.vehicle, settings), model.structure)
