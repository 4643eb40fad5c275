"""The goodness of fit's parametric bootstrap: what a model without missing effects leaves on this sweep.

A fitted model is turned into a plausible truth driven by the measured plate; its predicted readings plus
noise like the measured one make synthetic recordings, on which the model's structure is identified and
simulated again. Their gaps hold what a complete model still shows on this sweep (sensor noise, the curve's
discretisation of a smooth damper, identification errors) and nothing a missing effect adds.

The truth is the same structure identified at TRUTH_POINTS_FACTOR times the curve's resolution (the uniform
points and the low-speed knots, where a valve's dead band or bleed acts), its curve made smooth (a monotone
cubic through the points, linear beyond them). A truth at the doctor's own resolution is followed by the same
knots almost exactly, so the bootstrap would miss what the knots miss of a real damper's knee, which is most
of a complete model's gap. The truth's damper force rises with velocity (the points made non-decreasing
first): a curve that falls somewhere stands in for something the structure lacks (a zig-zag for a compliant
top mount), is not reproducible on its own response, and would excuse any gap. The hypothesis tested is "a
vehicle of this structure with a possible damper", not "this fit, whatever its shape".

The noise, per channel: the law measured on the output residual (estimator.noise_law: AR(1), white and
1/f parts and the readings' quantum), bounded by the measured reading's density (misfit and response are
each independent of it), fitted above the equations' low-pass cutoff (identify's, estimator.signals: the
band no fit of the model sees, so its residual is not shrunk by the fit's unknowns) and read at the
measured resolution.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from estimator.doctor.fitting import fit
from estimator.doctor.model import FittedModel, Reference
from estimator.doctor.simulation import diverged
from estimator.monotone import smooth_curve
from estimator.noise_law import measure_channel_noise, reading_quantum_m
from estimator.recording import Recording

TRUTH_POINTS_FACTOR = 2  # the plausible truth's curve has this many times the doctor's resolution


def plausible_truth(model: FittedModel, reference: Reference) -> FittedModel:
    """The plausible truth of a model fitted on `reference` (module docstring): its structure identified at
    TRUTH_POINTS_FACTOR times the points and low-speed knots, its damper curves non-decreasing and smooth."""
    settings = reference.settings
    points, low = settings.points, np.asarray(settings.low_speed_knots_m_s)
    fine = replace(
        settings,
        points=None if points is None else TRUTH_POINTS_FACTOR * points,
        low_speed_knots_m_s=tuple(np.linspace(low[0], low[-1], TRUTH_POINTS_FACTOR * (low.size - 1) + 1)),
    )
    on = Reference.of(reference.recording, model.vehicle, fine, reference.identified)
    truth = fit(on, model.structure, warm=model)
    return replace(truth, curve_override=tuple(smooth_curve(c) for c in truth.curves))


def synthetic_recordings(
    reference: Reference, predicted: dict[str, np.ndarray], residual: dict[str, np.ndarray], seeds: range
) -> list[Recording]:
    """Per seed, the predicted body and wheel readings read with the noise of the output residual (of the
    measured reading where it diverged) at the measured resolution; the plate as measured."""
    recording, noise = reference.recording, {}
    dt, band_from = recording.sample_time_s, reference.filters.equation_cutoff_Hz
    for name, r in residual.items():
        measured = recording.channels[name]
        r = measured if diverged(r, measured) else r
        noise[name] = measure_channel_noise(r, dt, band_from, reading_quantum_m(measured), measured)
    recordings = []
    for seed in seeds:
        rng, read = np.random.default_rng(seed), dict(recording.channels)
        for name, x in predicted.items():
            read[name] = noise[name].read(x, rng)
        recordings.append(Recording(recording.time_s, read, {"source": "model doctor: expected gap"}))
    return recordings
