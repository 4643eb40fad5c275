"""The gap and equation residual a model without missing effects reaches on this sweep: a parametric
bootstrap.

A fitted model is turned into a plausible truth, driven by the measured plate; its predicted readings plus
noise like the measured one make synthetic recordings, on which the model's structure is identified and
simulated again. The gap and objective of those re-identified models contain everything a complete model
still shows on this sweep (sensor noise, the piecewise-linear curve's discretisation of a smooth damper,
identification errors) and nothing a missing effect adds.

The truth. A real damper is smooth but not a curve of the doctor's resolution: a dyno table's knee near zero
velocity falls between the knots, and what the knots miss there is what dominates the gap of a complete
model. Measured on the independent world's clean recordings (simulators/independent, noise-free: the gap of
the 30-point starting model 41.8 µm, 1.4 µm with the world's own damper in its place, 13 µm with 60 points;
benchmarks/bench_doctor_independent.py): the smooth curve through the fitted points alone (the earlier
truth) is followed by the same knots almost exactly, so its expected gap missed that error altogether
(5 µm against 42). The truth is therefore the same structure identified with TRUTH_POINTS_FACTOR times the
points, its curve made smooth (a monotone cubic through the points, linear beyond them, as the simulator
treats tables): the finest curve the data supports, of which the doctor's knots miss what they miss on the
measurement.

The noise: per channel, the AR(1)-plus-white law and the reading resolution measured from the final model's
output residual (estimator.doctor.noise), not white noise of the top-band level.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from estimator.damper import PiecewiseLinearCurve
from estimator.doctor.fitting import fit
from estimator.doctor.model import FitSettings, FittedModel, Reference
from estimator.doctor.noise import ChannelNoise
from estimator.doctor.pchip import Pchip
from estimator.recording import Recording
from estimator.vehicle import VehicleConstant

SMOOTH_POINTS = 240
"""Knots of the dense table that represents the smooth truth's damper curve."""
TRUTH_POINTS_FACTOR = 2
"""The plausible truth's damper curve has this many times the doctor's points (module docstring)."""


def smooth_curve(curve: PiecewiseLinearCurve) -> PiecewiseLinearCurve:
    """A monotone cubic (PCHIP) through the curve's points, linear beyond them with the end slopes,
    tabulated densely over three times the curve's velocity span."""
    lo, hi = float(curve.velocity_m_s[0]), float(curve.velocity_m_s[-1])
    span = hi - lo
    interpolator = Pchip.through(curve.velocity_m_s, curve.force_N)
    inside = np.linspace(lo, hi, SMOOTH_POINTS)
    outside = np.array([lo - span, hi + span])
    grid = np.concatenate([outside[:1], inside, outside[1:]])
    force = np.concatenate(
        [
            [float(interpolator.value(lo)) - float(interpolator.slope(lo)) * span],
            interpolator.value(inside),
            [float(interpolator.value(hi)) + float(interpolator.slope(hi)) * span],
        ]
    )
    return PiecewiseLinearCurve(grid, force)


def smooth_truth(model: FittedModel) -> FittedModel:
    """The fitted model with its damper curves made smooth."""
    return replace(model, curve_override=tuple(smooth_curve(c) for c in model.curves))


def plausible_truth(
    model: FittedModel,
    recording: Recording,
    settings: FitSettings,
    identified: frozenset[VehicleConstant] = frozenset(),
) -> FittedModel:
    """A plausible truth for `model` (module docstring): its structure identified on the recording with
    TRUTH_POINTS_FACTOR times the points, the damper curves made smooth."""
    points = settings.points
    fine = replace(settings, points=None if points is None else TRUTH_POINTS_FACTOR * points)
    return smooth_truth(
        fit(Reference.of(recording, model.vehicle, fine, identified), model.structure, warm=model)
    )


def synthetic_recording(
    recording: Recording, predicted: dict[str, np.ndarray], noise: dict[str, ChannelNoise], seed: int
) -> Recording:
    """Predicted body and wheel readings as sensors with the measured noise read them; the plate as
    measured."""
    rng = np.random.default_rng(seed)
    channels = dict(recording.channels)
    for name, x in predicted.items():
        channels[name] = noise[name].read(x, rng)
    return Recording(recording.time_s, channels, {"source": "model doctor: expected gap"})


def refit_on(synthetic: Recording, model: FittedModel, reference: Reference) -> FittedModel:
    """The model's structure identified on the synthetic recording (the reference's settings, hinge knots
    and identified constants), started from the model's own unknowns and channel parameters (the synthetic
    recording is the model's response plus noise, so its optimum lies near them)."""
    on = Reference.of(synthetic, model.vehicle, reference.settings, reference.identified)
    return fit(replace(on, knots_m=reference.knots_m), model.structure, warm=model)
