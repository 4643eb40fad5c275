"""Laser channels of the foreign world: what the amplifier does to a displacement before the DAQ reads it.

Per channel, in this order:
1. a filter on the true displacement: none, a first-order lag (time constant τ: y' = (x − y)/τ, applied
   exactly for an input linear between the points of a fine grid), or the ZX-LDA amplifier's moving average
   of the last N samples of its own 150 µs measurement period (average counts 1, 2, 4, ... 4096 in its
   manual), read by the DAQ at its sample instants (the latest finished average, so the reading also holds
   for up to one measurement period);
2. a gain error (a wrong head range or calibration): reading = gain × displacement about the zero;
3. noise of a drawn RMS: white, AR(1) (lag-1 correlation ρ) or 1/f-like (power spectral density ∝ 1/f
   above 0.1 Hz, flat below), the coloured kinds normalised to the drawn RMS exactly;
4. quantisation to the display resolution (1 µm).
The noise is added after the filter (it is the output stage's and the DAQ's), so its RMS is what was drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.signal import lfilter, lfilter_zi

from simulators.independent.sensors import SensorNoise

AMPLIFIER_PERIOD_S = 150e-6
"""The ZX-LDA11/41 amplifier's measurement period (OMRON ZX series manual, ratings)."""
PINK_CORNER_HZ = 0.1
"""Below this the 1/f noise's spectrum is flat (a finite variance)."""
LAG_GRID_DIVISIONS = 16
"""The first-order lag runs on a grid this many times finer than the sample time."""


@dataclass(frozen=True)
class FirstOrderLag:
    time_constant_s: float

    @property
    def equivalent_delay_s(self) -> float:
        """The low-frequency group delay: τ."""
        return self.time_constant_s

    def apply(self, values: np.ndarray, step_s: float) -> np.ndarray:
        """Exact response, from rest at values[0], to an input linear between samples step_s apart."""
        a = math.exp(-step_s / self.time_constant_s)
        gamma = self.time_constant_s / step_s * (1.0 - a)
        b0, b1 = 1.0 - gamma, gamma - a
        b, den = [b0, b1], [1.0, -a]
        return lfilter(b, den, values, zi=lfilter_zi(b, den) * values[0])[0]


@dataclass(frozen=True)
class MovingAverage:
    count: int
    period_s: float = AMPLIFIER_PERIOD_S

    def __post_init__(self) -> None:
        if self.count < 1:
            raise ValueError("a moving average needs at least one sample")

    @property
    def equivalent_delay_s(self) -> float:
        """The average's group delay, (N − 1)/2 measurement periods, plus half a period of holding."""
        return (0.5 * (self.count - 1) + 0.5) * self.period_s

    def tick_indices(self, time_s: np.ndarray) -> np.ndarray:
        """The measurement ticks (multiples of period_s) each sample averages: (samples, count)."""
        last = np.floor(time_s / self.period_s + 1e-9).astype(np.int64)
        return last[:, None] - np.arange(self.count)[None, :]


ChannelFilter = FirstOrderLag | MovingAverage | None


@dataclass(frozen=True)
class ChannelNoise:
    kind: Literal["white", "ar1", "pink"]
    rms_m: float
    lag1_correlation: float = 0.0

    def draw(self, samples: int, sample_time_s: float, rng: np.random.Generator) -> np.ndarray:
        if self.kind == "white":
            return rng.standard_normal(samples) * self.rms_m
        if self.kind == "ar1":
            raw = SensorNoise(1.0, self.lag1_correlation, 0.0).noise(samples, rng)
        else:
            spectrum = np.fft.rfft(rng.standard_normal(samples))
            frequency = np.fft.rfftfreq(samples, sample_time_s)
            spectrum /= np.sqrt(np.maximum(frequency, PINK_CORNER_HZ))
            spectrum[0] = 0.0
            raw = np.fft.irfft(spectrum, samples)
        raw = raw - np.mean(raw)
        return raw * (self.rms_m / float(np.sqrt(np.mean(raw * raw))))


@dataclass(frozen=True)
class Channel:
    """One laser channel: its filter, gain, noise and resolution."""

    filter: ChannelFilter = None
    gain: float = 1.0
    noise: ChannelNoise = ChannelNoise("white", 5e-6)
    quantum_m: float = 1e-6

    def finish(self, filtered_m: np.ndarray, sample_time_s: float, rng: np.random.Generator) -> np.ndarray:
        """Gain, noise and quantisation of the filtered displacement at the sample instants."""
        reading = self.gain * filtered_m + self.noise.draw(filtered_m.size, sample_time_s, rng)
        if self.quantum_m:
            reading = np.round(reading / self.quantum_m) * self.quantum_m
        return reading
