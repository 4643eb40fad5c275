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

The noise, per channel: a laser's filter colours it (AR(1)), so the density at the top of the band
understates it where the vehicle responds. The smaller of the output residual's and the measured reading's
densities bounds it per frequency (misfit and response are each independent of it); above the equations'
low-pass cutoff (identify's, estimator.signals: the band no fit of the model sees, so its residual is not
shrunk by the fit's unknowns) it is fitted by S(f) = a/(1 − 2ρ·cos ω + ρ²) + b + c/f (a, b, c ≥ 0, ρ on a
grid; AR(1), white and 1/f parts), extrapolated to the whole band, and read at the measured resolution.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from estimator.damper import PiecewiseLinearCurve
from estimator.digital_filters import first_order_filter, welch_density
from estimator.doctor.fitting import fit
from estimator.doctor.model import FittedModel, Reference
from estimator.doctor.simulation import diverged
from estimator.linear_algebra import small_nnls
from estimator.monotone import Pchip, increasing
from estimator.recording import Recording

SMOOTH_POINTS = 240  # knots of the dense table of the smooth truth's damper curve
TRUTH_POINTS_FACTOR = 2  # the plausible truth's curve has this many times the doctor's resolution


def smooth_curve(curve: PiecewiseLinearCurve) -> PiecewiseLinearCurve:
    """A monotone cubic (PCHIP) through the curve's points made non-decreasing (increasing), linear beyond
    them with the end slopes, tabulated densely over three times the curve's velocity span."""
    lo, hi = float(curve.velocity_m_s[0]), float(curve.velocity_m_s[-1])
    span = hi - lo
    cubic = Pchip.through(curve.velocity_m_s, increasing(curve.force_N))
    inside = np.linspace(lo, hi, SMOOTH_POINTS)
    below = float(cubic.value(lo)) - float(cubic.slope(lo)) * span
    above = float(cubic.value(hi)) + float(cubic.slope(hi)) * span
    grid = np.concatenate([[lo - span], inside, [hi + span]])
    return PiecewiseLinearCurve(grid, np.concatenate([[below], cubic.value(inside), [above]]))


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


LAG1_GRID = np.linspace(0.0, 0.98, 99)  # candidate lag-1 correlations of the AR(1) part
MIN_BINS = 8
"""Fewest density bins a fit uses; with fewer in the noise band the whole band above 0 Hz is used."""


@dataclass(frozen=True)
class ChannelNoise:
    """Noise of one channel: an AR(1) part e[n] = ρ·e[n−1] + w[n] of standard deviation coloured_m, white
    noise of standard deviation white_m, 1/f noise of one-sided density pink_m2/f (drawn at sample_time_s;
    0: none), readings rounded to quantum_m (0: not quantised)."""

    coloured_m: float
    lag1_correlation: float
    white_m: float
    quantum_m: float = 0.0
    pink_m2: float = 0.0
    sample_time_s: float = 0.0

    @property
    def rms_m(self) -> float:
        return float(np.hypot(self.coloured_m, self.white_m))

    def pink(self, samples: int, rng: np.random.Generator) -> np.ndarray:
        """The 1/f part: white noise shaped to the density pink_m2/f (flat below 1/(samples·Δt))."""
        if self.pink_m2 <= 0.0 or self.sample_time_s <= 0.0:
            return np.zeros(samples)
        dt = self.sample_time_s
        density = self.pink_m2 / np.maximum(np.fft.rfftfreq(samples, dt), 1.0 / (samples * dt))
        # unit white noise has the one-sided density 2·Δt
        spectrum = np.fft.rfft(rng.standard_normal(samples)) * np.sqrt(density / (2.0 * dt))
        return np.fft.irfft(spectrum, samples)

    def draw(self, samples: int, rng: np.random.Generator) -> np.ndarray:
        """A stationary sequence of this noise (the AR(1) part started from its stationary law)."""
        rho = self.lag1_correlation
        innovation = rng.standard_normal(samples) * self.coloured_m * np.sqrt(1.0 - rho * rho)
        innovation[0] = innovation[0] / np.sqrt(1.0 - rho * rho)
        coloured = first_order_filter((1.0, 0.0), -rho, innovation)
        return coloured + rng.standard_normal(samples) * self.white_m + self.pink(samples, rng)

    def read(self, true_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """What a sensor with this noise and resolution reads of `true_m`."""
        reading = true_m + self.draw(true_m.size, rng)
        q = self.quantum_m
        return np.round(reading / q) * q if q > 0.0 else reading


def reading_quantum_m(x: np.ndarray) -> float:
    """The smallest step between distinct readings when every reading is a whole multiple of it, else 0."""
    values = np.unique(x)
    step = float(np.min(np.diff(values))) if values.size >= 3 else 0.0
    if step <= 0.0 or np.max(np.abs(x / step - np.round(x / step))) > 1e-3:
        return 0.0
    return step


def measure_channel_noise(
    residual_m: np.ndarray,
    sample_time_s: float,
    band_from_Hz: float,
    quantum_m: float = 0.0,
    measured_m: np.ndarray | None = None,
) -> ChannelNoise:
    """The noise law of the residual's density above band_from_Hz, bounded by the measured reading's."""
    fs = 1.0 / sample_time_s
    x = residual_m - np.mean(residual_m)
    nperseg = int(min(x.size, max(256, 2 ** int(np.log2(fs)))))
    frequency, density = welch_density(x, fs, nperseg)
    if measured_m is not None:
        density = np.minimum(density, welch_density(measured_m - np.mean(measured_m), fs, nperseg)[1])
    band = (frequency >= band_from_Hz) & (density > 0.0)
    if np.count_nonzero(band) < MIN_BINS:
        band = (frequency > 0.0) & (density > 0.0)
    f, p = frequency[band], density[band]
    if f.size == 0:
        return ChannelNoise(0.0, 0.0, 0.0, quantum_m)
    cos_omega = np.cos(2.0 * np.pi * f * sample_time_s)

    shapes = 1.0 / (1.0 - 2.0 * LAG1_GRID[:, None] * cos_omega[None, :] + LAG1_GRID[:, None] ** 2)
    designs = np.stack(
        [shapes / p, np.broadcast_to(1.0 / p, shapes.shape), np.broadcast_to(1.0 / (f * p), shapes.shape)],
        axis=2,
    )
    coefficients, misfits = small_nnls(designs, np.ones(f.size))
    best = int(np.argmin(misfits))  # the first of equal misfits, as min over the grid in order
    rho, (a, b, c) = float(LAG1_GRID[best]), (float(v) for v in coefficients[best])
    # one-sided density of AR(1) with innovation variance s²: 2·s²·Δt / |1 − ρe^{−iω}|²; its variance
    # s²/(1 − ρ²); white noise of variance σ²: 2·σ²·Δt
    coloured_variance = a / (2.0 * sample_time_s) / (1.0 - rho * rho)
    # the rounding of the synthetic readings adds the quantisation's own q²/12 again
    white_variance = max(0.0, b / (2.0 * sample_time_s) - quantum_m * quantum_m / 12.0)
    return ChannelNoise(
        float(np.sqrt(coloured_variance)), rho, float(np.sqrt(white_variance)), quantum_m, c, sample_time_s
    )


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
