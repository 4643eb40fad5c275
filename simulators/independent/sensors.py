"""Laser channels of the independent world: noise (white, or AR(1)-coloured as a laser's internal filter
colours it) and quantisation to the amplifier's display resolution. Delays and zero errors are applied
before, to the true displacement (world.py samples the continuous solution at t − delay)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter


@dataclass(frozen=True)
class SensorNoise:
    """rms_m: standard deviation of the noise; lag1_correlation: ρ of an AR(1) process
    e[n] = ρ·e[n−1] + √(1−ρ²)·σ·w[n] (0 = white); quantum_m: the reading's resolution (0 = none)."""

    rms_m: float = 5e-6
    lag1_correlation: float = 0.0
    quantum_m: float = 1e-6

    def __post_init__(self) -> None:
        if not 0.0 <= self.lag1_correlation < 1.0:
            raise ValueError("lag1_correlation must be in [0, 1)")
        if self.rms_m < 0 or self.quantum_m < 0:
            raise ValueError("rms_m and quantum_m must be >= 0")

    def noise(self, samples: int, rng: np.random.Generator) -> np.ndarray:
        """A stationary AR(1) sequence of the requested RMS (the first value from the stationary law)."""
        white = rng.standard_normal(samples) * self.rms_m
        rho = self.lag1_correlation
        if rho == 0.0:
            return white
        innovation = np.sqrt(1.0 - rho * rho) * white
        innovation[0] = white[0]
        return lfilter([1.0], [1.0, -rho], innovation)

    def read(self, true_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        reading = true_m + self.noise(true_m.size, rng)
        if self.quantum_m:
            reading = np.round(reading / self.quantum_m) * self.quantum_m
        return reading
