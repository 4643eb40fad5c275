"""The goodness of fit's parametric bootstrap: what a model without missing effects leaves on this sweep.

A fitted model is turned into a plausible truth driven by the measured plate; its predicted readings plus
noise like the measured one make synthetic recordings, on which the model's structure is identified and
simulated again. Their gaps hold what a complete model still shows on this sweep (sensor noise, the curve's
discretisation of a smooth damper, identification errors) and nothing a missing effect adds.

The truth: the structure identified at identify's finest resolution (truth_settings), its curve a monotone
cubic through the points (linear beyond): at the doctor's own resolution its knots would follow it almost
exactly, missing what they miss of a real damper's knee. Its force rises with velocity: a curve that falls
stands in for something the structure lacks (a zig-zag for a compliant top mount) and would excuse any gap.
The hypothesis tested is "a vehicle of this structure with a damper identify can take", not "this fit".

The noise, per channel: the law of the output residual (estimator.noise_law: AR(1), white, 1/f, quantum),
bounded by the measured reading's density, fitted above the equations' low-pass cutoff (the band no fit
sees: its residual is not shrunk by the fit's unknowns), read at the measured resolution.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from estimator.doctor.fitting import fit
from estimator.doctor.model import FitSettings, FittedModel, Reference
from estimator.doctor.simulation import diverged
from estimator.equations import default_points
from estimator.identify_options import IdentifyOptions
from estimator.monotone import smooth_curve
from estimator.noise_law import measure_channel_noise, reading_quantum_m
from estimator.recording import Recording
from estimator.vehicle import VehicleParameters


def truth_settings(settings: FitSettings, vehicle: VehicleParameters) -> FitSettings:
    """The truth's resolution: identify's finest (IdentifyOptions.MAX_POINTS: more resolve nothing the
    recording carries; an axle's side half, as identify's default halves it), each interval between low-speed
    knots (a valve's bleed or dead band) split in as many as that multiplies the doctor's points, or none."""
    points, low = settings.points or default_points(vehicle), np.asarray(settings.low_speed_knots_m_s)
    ratio = max(1, round((finest := IdentifyOptions.MAX_POINTS // vehicle.wheels) / points))
    knots = tuple(float(k) for k in np.linspace(low[0], low[-1], ratio * (low.size - 1) + 1))
    return replace(settings, points=max(finest, points), low_speed_knots_m_s=knots)


def plausible_truth(model: FittedModel, reference: Reference) -> FittedModel:
    """The plausible truth of a model fitted on `reference` (module docstring), at truth_settings'."""
    fine = truth_settings(reference.settings, model.vehicle)
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
