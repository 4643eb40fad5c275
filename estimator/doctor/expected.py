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
resolution (the uniform points and the low-speed knots, whose spacing near zero velocity is where a valve's
dead band or bleed acts), its curve made smooth (a monotone cubic through the points, linear beyond them, as
the simulator treats tables): the finest curve the data supports, of which the doctor's knots miss what they
miss on the measurement.

The truth is a physically possible one: its damper force rises with velocity (the fitted points made
non-decreasing by isotonic regression before the cubic). A model that needs a curve that falls somewhere is
standing in for something its structure lacks (a damper on a compliant top mount fitted with a 500 N zig-zag
at 120-360 mm/s); identified again on its own response, such a curve is not reproducible (gaps twice the
measured one), and a null built on it would excuse any gap. The hypothesis the bootstrap tests is "a vehicle
of this structure with a possible damper", not "this fit, whatever its shape".

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
"""The plausible truth's damper curve has this many times the doctor's resolution (module docstring)."""


def increasing(values: np.ndarray) -> np.ndarray:
    """The non-decreasing sequence nearest to `values` in least squares (isotonic regression by pooling
    adjacent violators: a run that falls is replaced by its mean, merged backwards until none falls)."""
    means: list[float] = []
    sizes: list[int] = []
    for value in np.asarray(values, dtype=float):
        means.append(float(value))
        sizes.append(1)
        while len(means) > 1 and means[-2] > means[-1]:
            size = sizes[-2] + sizes[-1]
            means[-2] = (means[-2] * sizes[-2] + means[-1] * sizes[-1]) / size
            sizes[-2] = size
            del means[-1], sizes[-1]
    return np.repeat(means, sizes)


def smooth_curve(curve: PiecewiseLinearCurve) -> PiecewiseLinearCurve:
    """A monotone cubic (PCHIP) through the curve's points made non-decreasing (increasing), linear beyond
    them with the end slopes, tabulated densely over three times the curve's velocity span."""
    lo, hi = float(curve.velocity_m_s[0]), float(curve.velocity_m_s[-1])
    span = hi - lo
    interpolator = Pchip.through(curve.velocity_m_s, increasing(curve.force_N))
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
    TRUTH_POINTS_FACTOR times the points and the low-speed knots' spacing divided by it, the damper curves
    made non-decreasing and smooth."""
    points, low = settings.points, np.asarray(settings.low_speed_knots_m_s)
    fine = replace(
        settings,
        points=None if points is None else TRUTH_POINTS_FACTOR * points,
        low_speed_knots_m_s=tuple(np.linspace(low[0], low[-1], TRUTH_POINTS_FACTOR * (low.size - 1) + 1)),
    )
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
