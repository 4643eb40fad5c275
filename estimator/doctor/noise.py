"""The sensor noise of a recording, measured from the data itself, so that the expected gap's synthetic
recordings carry noise like the measured one (level, colour and reading resolution), not white noise of a
level read off the top of the band.

A laser's internal filter colours its noise: a first-order filter makes it an AR(1) process, whose density
rises towards low frequencies, where the vehicle's response and the equations of motion are. Its density at
the top of the band (what estimator.signals reads as the noise floor) then understates both the noise's RMS
and its density in the signal band (AR(1) with ρ 0.67: a quarter of the RMS² at Nyquist, five times the
white density at zero frequency). Measured on the independent world's clean recordings
(benchmarks/bench_doctor_independent.py), white bootstrap noise of that level left the expected equation
residual at a fifth of what the coloured noise gives.

How it is measured: the output residual of the final model (simulated from the measured plate minus the
measured reading) holds the noise plus the model's own error; the model's error lies in the band the
vehicle responds in, the noise everywhere. The noise's density is at most the residual's (misfit and noise
are independent) and at most the measured reading's (response and noise are too), so per frequency the
smaller of the two bounds it: a model whose simulated wheel rings at 30-80 Hz, where the measured wheel
does not move, makes the residual's density there twenty times the reading's, and that ringing is not the
sensor's noise. Above NOISE_BAND_FROM × the excitation's top frequency that bound is fitted, per channel,
with an AR(1) density plus a white floor (sensor white noise and the reading's quantisation),
S(f) = a/(1 − 2ρ·cos ω + ρ²) + b, a, b ≥ 0, ρ on a grid, least squares on the density relative to the
measured one. The fitted law is extrapolated to the whole band.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.digital_filters import first_order_filter, welch_density

NOISE_BAND_FROM = 2.0
"""The noise is fitted above this multiple of the excitation's top frequency (the vehicle responds below)."""
LAG1_GRID = np.linspace(0.0, 0.98, 99)
"""Candidate lag-1 correlations of the AR(1) part."""
MIN_BINS = 8
"""Fewest density bins a fit uses; with fewer in the noise band the whole band above 0 Hz is used."""


@dataclass(frozen=True)
class ChannelNoise:
    """Noise of one channel: an AR(1) part e[n] = ρ·e[n−1] + w[n] of standard deviation coloured_m, white
    noise of standard deviation white_m and 1/f noise of one-sided density pink_m2·Hz⁻¹·(1 Hz / f) above
    the record's lowest frequency (flat below it); readings rounded to quantum_m (0: not quantised).
    sample_time_s: what the 1/f part is drawn at (0: no 1/f part)."""

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
        """The 1/f part: white noise shaped in the frequency domain to the density pink_m2/f (flat below the
        record's lowest frequency, 1/(samples·Δt))."""
        if self.pink_m2 <= 0.0 or self.sample_time_s <= 0.0:
            return np.zeros(samples)
        dt = self.sample_time_s
        frequency = np.fft.rfftfreq(samples, dt)
        lowest = 1.0 / (samples * dt)
        density = self.pink_m2 / np.maximum(frequency, lowest)
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
        if self.quantum_m > 0.0:
            reading = np.round(reading / self.quantum_m) * self.quantum_m
        return reading


def reading_quantum_m(x: np.ndarray) -> float:
    """The resolution the readings are rounded to: the smallest step between distinct readings when every
    reading is a whole multiple of it (0 when the readings are not quantised, or too finely to matter)."""
    values = np.unique(x)
    if values.size < 3:
        return 0.0
    step = float(np.min(np.diff(values)))
    if step <= 0.0:
        return 0.0
    multiples = x / step
    if np.max(np.abs(multiples - np.round(multiples))) > 1e-3:
        return 0.0
    return step


def _ar1_shape(frequency_Hz: np.ndarray, sample_time_s: float, rho: float) -> np.ndarray:
    omega = 2.0 * np.pi * frequency_Hz * sample_time_s
    return 1.0 / (1.0 - 2.0 * rho * np.cos(omega) + rho * rho)


def small_nnls(design: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float]:
    """scipy.optimize.nnls for a design of a few columns: x ≥ 0 minimising ||design·x − target||, and that
    norm, by trying every set of free columns (the optimum is the unconstrained least squares on one of
    them with the rest at zero). Why not scipy's: importing scipy.optimize costs a diagnosis about 0.12 s
    for this one small fit. On a tie the set with the fewest and earliest columns wins (collinear columns:
    ρ = 0 makes the AR(1) shape white)."""
    columns = design.shape[1]
    best: tuple[float, np.ndarray] = (float(np.linalg.norm(target)), np.zeros(columns))
    tie = 1e-12 * float(np.linalg.norm(target))
    subsets = sorted(
        (tuple(k for k in range(columns) if mask >> k & 1) for mask in range(1, 2**columns)),
        key=lambda subset: (len(subset), subset),
    )
    for subset in subsets:
        part = design[:, subset]
        solution = np.linalg.lstsq(part, target, rcond=None)[0]
        if np.any(solution < 0.0):
            continue
        x = np.zeros(columns)
        x[list(subset)] = solution
        misfit = float(np.linalg.norm(design @ x - target))
        if misfit < best[0] - tie:
            best = (misfit, x)
    return best[1], best[0]


def measure_channel_noise(
    residual_m: np.ndarray,
    sample_time_s: float,
    band_from_Hz: float,
    quantum_m: float = 0.0,
    measured_m: np.ndarray | None = None,
) -> ChannelNoise:
    """The AR(1)-plus-white law fitted to the residual's density above band_from_Hz, bounded per frequency
    by the measured reading's own density when given (module docstring)."""
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
    best: tuple[float, float, float, float, float] | None = None
    for rho in LAG1_GRID:
        shape = _ar1_shape(f, sample_time_s, float(rho))
        design = np.column_stack([shape / p, 1.0 / p, 1.0 / (f * p)])
        (a, b, c), misfit = small_nnls(design, np.ones(f.size))
        if best is None or misfit < best[0]:
            best = (float(misfit), float(rho), float(a), float(b), float(c))
    assert best is not None
    _, rho, a, b, c = best
    # one-sided density of AR(1) with innovation variance s²: 2·s²·Δt / |1 − ρe^{−iω}|²; its variance
    # s²/(1 − ρ²); white noise of variance σ²: 2·σ²·Δt
    coloured_variance = a / (2.0 * sample_time_s) / (1.0 - rho * rho)
    # the rounding of the synthetic readings adds the quantisation's own q²/12 again
    white_variance = max(0.0, b / (2.0 * sample_time_s) - quantum_m * quantum_m / 12.0)
    return ChannelNoise(
        float(np.sqrt(coloured_variance)), rho, float(np.sqrt(white_variance)), quantum_m, c, sample_time_s
    )


def measure_noise(
    residual_m: dict[str, np.ndarray],
    measured_m: dict[str, np.ndarray],
    sample_time_s: float,
    excitation_top_Hz: float,
) -> dict[str, ChannelNoise]:
    """Per channel: the noise of the output residual (module docstring), with the resolution of the
    channel's measured readings."""
    band_from = NOISE_BAND_FROM * excitation_top_Hz
    return {
        name: measure_channel_noise(
            r, sample_time_s, band_from, reading_quantum_m(measured_m[name]), measured_m[name]
        )
        for name, r in residual_m.items()
    }
