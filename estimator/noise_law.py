"""A sensor channel's noise law measured from a residual and drawn again: an AR(1) part (a laser's filter
colours it, so the density at the top of the band understates it where the vehicle responds), white noise,
1/f noise, and the readings' quantum. The model doctor's bootstrap (estimator.doctor.expected) reads its
synthetic recordings with it: the recording's own noise, coloured and quantised, not an idealised one.

The law is fitted to the residual's Welch density above a band edge, bounded per frequency by the measured
reading's own density: S(f) = a/(1 − 2ρ·cos ω + ρ²) + b + c/f (a, b, c ≥ 0 by non-negative least squares in
relative error, ρ on a grid; AR(1), white and 1/f parts), extrapolated to the whole band."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.digital_filters import first_order_filter, welch_density
from estimator.linear_algebra import small_nnls

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
