"""The sensor noise of a recording, measured from the data, for the expected gap's synthetic recordings.

A laser's filter colours its noise (AR(1)): the density at the top of the band understates it where the
vehicle responds. The smaller of the output residual's and the measured reading's densities bounds the
noise's per frequency (misfit and response are each independent of it); above NOISE_BAND_FROM × the
excitation's top frequency it is fitted by S(f) = a/(1 − 2ρ·cos ω + ρ²) + b + c/f (a, b, c ≥ 0, ρ on a
grid; AR(1), white and 1/f parts), extrapolated to the whole band.
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


def small_nnls(design: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float]:
    """x ≥ 0 minimising ||design·x − target||, and that norm, for a design of a few columns: the least
    squares on every set of free columns (the rest at zero); on a tie the fewest and earliest columns win
    (ρ = 0 makes the AR(1) shape white). Not scipy.optimize.nnls: importing it costs more than the fit."""
    columns = design.shape[1]
    best: tuple[float, np.ndarray] = (float(np.linalg.norm(target)), np.zeros(columns))
    tie = 1e-12 * float(np.linalg.norm(target))
    subsets = sorted(
        (tuple(k for k in range(columns) if mask >> k & 1) for mask in range(1, 2**columns)),
        key=lambda subset: (len(subset), subset),
    )
    for subset in subsets:
        solution = np.linalg.lstsq(design[:, subset], target, rcond=None)[0]
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
    """The noise law fitted to the residual's density above band_from_Hz, bounded by the measured reading's
    density when given (module docstring)."""
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

    def fitted(rho: float) -> tuple[float, float, float, float, float]:
        shape = 1.0 / (1.0 - 2.0 * rho * cos_omega + rho * rho)
        (a, b, c), misfit = small_nnls(np.column_stack([shape / p, 1.0 / p, 1.0 / (f * p)]), np.ones(f.size))
        return float(misfit), rho, float(a), float(b), float(c)

    _, rho, a, b, c = min(map(fitted, map(float, LAG1_GRID)), key=lambda fit: fit[0])
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
    """Per channel: the noise of the output residual, with the resolution of the measured readings."""
    band_from = NOISE_BAND_FROM * excitation_top_Hz
    return {
        name: measure_channel_noise(
            r, sample_time_s, band_from, reading_quantum_m(measured_m[name]), measured_m[name]
        )
        for name, r in residual_m.items()
    }
