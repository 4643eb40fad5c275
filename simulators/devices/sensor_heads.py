"""Laser displacement sensor heads as the simulated amplifiers see them: measuring range, resolution, noise.

A `SimulatedHead` is bound to one channel of the bench physics ("x_s", "x_t", "x_r", ...) and reads it at
the bench clock's current time. Mounting convention: the head measures along the vertical axis and its
reading is the deviation from the centre of its measuring range, positive TOWARD the head. With `sign=+1`
the head sits above the target looking down, so an upward displacement (the bench's positive direction)
reads positive; `sign=-1` is a head below looking up. `static_offset_m` is where the target's static
position sits relative to the measuring centre (positive = closer to the head), so

    reading_m = static_offset_m + sign * bench.position_m(channel)      (then noise, then quantisation)

and the target is out of range when |static_offset_m + sign * position| > half_range_m.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from simulators.coupling import PlatePhysics


@dataclass(frozen=True)
class HeadModel:
    """Catalogue data of a head. noise_sigma_m is the standard deviation of the Gaussian noise added to
    each sample; the default models use half the catalogue resolution (a modelling choice: OMRON's
    resolution figure is a peak-to-peak value under averaging)."""

    name: str
    centre_distance_m: float
    half_range_m: float
    resolution_m: float
    noise_sigma_m: float

    def __post_init__(self) -> None:
        if self.half_range_m <= 0 or self.resolution_m <= 0 or self.noise_sigma_m < 0:
            raise ValueError(f"{self.name}: range and resolution must be > 0, noise >= 0")


ZX_LD40 = HeadModel(
    "ZX-LD40", centre_distance_m=0.040, half_range_m=0.010, resolution_m=2e-6, noise_sigma_m=1e-6
)
"""ZX-LD40: 40 ± 10 mm, resolution 2 µm."""

ZX_LD100 = HeadModel(
    "ZX-LD100", centre_distance_m=0.100, half_range_m=0.040, resolution_m=16e-6, noise_sigma_m=8e-6
)
"""ZX-LD100: 100 ± 40 mm, resolution 16 µm."""


class SimulatedHead:
    """A head watching one bench channel. `measure_m()` is one sample at bench.clock.now_s()."""

    def __init__(
        self,
        model: HeadModel,
        bench: PlatePhysics,
        channel: str,
        *,
        sign: int = 1,
        static_offset_m: float = 0.0,
        noise_sigma_m: float | None = None,
        rng: np.random.Generator | None = None,
        seed: int = 0,
    ) -> None:
        """noise_sigma_m overrides the model's noise (0 for exact readings in tests); rng, else a Generator
        seeded with `seed`, draws the noise, so a run is reproducible."""
        if sign not in (1, -1):
            raise ValueError(f"sign must be +1 or -1, got {sign}")
        self.model = model
        self.bench = bench
        self.channel = channel
        self.sign = sign
        self.static_offset_m = static_offset_m
        self.noise_sigma_m = model.noise_sigma_m if noise_sigma_m is None else noise_sigma_m
        self._rng = rng if rng is not None else np.random.default_rng(seed)
        self._lock = threading.Lock()

    def true_deviation_m(self, at_s: float | None = None) -> float:
        """Noise-free deviation from the measuring centre, positive toward the head, now or at the recent
        past instant at_s (s)."""
        position_m = (
            self.bench.position_m(self.channel) if at_s is None else self.bench.position_m(self.channel, at_s)
        )
        return self.static_offset_m + self.sign * position_m

    def in_range(self, deviation_m: float) -> bool:
        return abs(deviation_m) <= self.model.half_range_m

    def quantise_m(self, value_m: float) -> float:
        step = self.model.resolution_m
        return round(value_m / step) * step

    def measure_many_m(self, times_s: np.ndarray) -> np.ndarray:
        """Readings at many recent instants at once (as measure_m, vectorised); NaN where out of range."""
        deviation_m = self.static_offset_m + self.sign * self.bench.positions_m(self.channel, times_s)
        inside = np.abs(deviation_m) <= self.model.half_range_m
        if self.noise_sigma_m > 0:
            with self._lock:
                deviation_m = deviation_m + self._rng.normal(0.0, self.noise_sigma_m, deviation_m.shape)
        step = self.model.resolution_m
        return np.where(inside, np.round(deviation_m / step) * step, np.nan)

    def measure_m(self, at_s: float | None = None) -> float | None:
        """One reading (now, or at the past instant at_s): deviation + Gaussian noise, quantised to the
        resolution; None when out of range."""
        deviation_m = self.true_deviation_m(at_s)
        if not self.in_range(deviation_m):
            return None
        if self.noise_sigma_m > 0:
            with self._lock:
                deviation_m += float(self._rng.normal(0.0, self.noise_sigma_m))
        return self.quantise_m(deviation_m)
