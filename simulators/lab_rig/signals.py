"""Signals of the lab rig given analytically (value and exact rate at any time), so that solve_ivp sees a
smooth forcing: a band-limited multisine (the random road, and the actuator's unrecorded command) and a
sequence of smooth steps and bumps. The 0-20 Hz chirp is the independent world's (simulators.independent.
excitation.Chirp), which has the same `motion(t) -> (value, rate)` form.

Every signal starts and ends at rest: a multisine is faded in and out by a raised cosine; a step or bump
is a raised-cosine transition, and the sequence returns to zero before it ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np


class Signal(Protocol):
    """What the rig is driven by: t -> (value, d value / dt). The plate's position in m; a command in N."""

    def motion(self, t_s: float) -> tuple[float, float]: ...


def _raised_cosine(u: float) -> tuple[float, float]:
    """S(u) rising from 0 at u <= 0 to 1 at u >= 1, and dS/du."""
    if u <= 0.0:
        return 0.0, 0.0
    if u >= 1.0:
        return 1.0, 0.0
    return 0.5 * (1.0 - math.cos(math.pi * u)), 0.5 * math.pi * math.sin(math.pi * u)


@dataclass(frozen=True)
class Multisine:
    """Σ a_k·sin(2π f_k t + φ_k) under a window that rises over fade_s, holds, and falls to zero at
    duration_s (then stays zero). A random-phase multisine of many components is a band-limited random
    signal with an exactly known rate."""

    frequencies_Hz: tuple[float, ...]
    amplitudes: tuple[float, ...]
    phases_rad: tuple[float, ...]
    duration_s: float
    fade_s: float = 0.5

    def __post_init__(self) -> None:
        if not len(self.frequencies_Hz) == len(self.amplitudes) == len(self.phases_rad):
            raise ValueError("a multisine needs as many amplitudes and phases as frequencies")
        if not self.duration_s > 2.0 * self.fade_s:
            raise ValueError("the multisine must be longer than its fade-in and fade-out")

    @classmethod
    def random(
        cls,
        rng: np.random.Generator,
        band_Hz: tuple[float, float],
        rms: float,
        duration_s: float,
        components: int = 60,
        slope: float = 0.0,
        fade_s: float = 0.5,
    ) -> Multisine:
        """Random frequencies in the band, random phases, amplitudes ∝ f^(−slope) (0: flat; 1: a road's
        displacement spectrum falling with frequency), scaled to the requested RMS (before the fades)."""
        low, high = band_Hz
        frequencies = np.sort(rng.uniform(low, high, components))
        shape = frequencies ** (-slope)
        amplitudes = shape * rms * math.sqrt(2.0) / math.sqrt(float(np.sum(shape**2)))
        phases = rng.uniform(0.0, 2.0 * math.pi, components)
        return cls(
            tuple(map(float, frequencies)),
            tuple(map(float, amplitudes)),
            tuple(map(float, phases)),
            duration_s,
            fade_s,
        )

    def _window(self, t_s: float) -> tuple[float, float]:
        rise, rise_rate = _raised_cosine(t_s / self.fade_s)
        fall, fall_rate = _raised_cosine((self.duration_s - t_s) / self.fade_s)
        return rise * fall, (rise_rate * fall - rise * fall_rate) / self.fade_s

    @cached_property
    def _arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """ω, φ, a and a·ω as arrays, made once (the right-hand side asks for the signal at every stage)."""
        omega = 2.0 * np.pi * np.asarray(self.frequencies_Hz)
        amplitudes = np.asarray(self.amplitudes)
        return omega, np.asarray(self.phases_rad), amplitudes, amplitudes * omega

    def motion(self, t_s: float) -> tuple[float, float]:
        window, window_rate = self._window(t_s)
        if window == 0.0 and window_rate == 0.0:
            return 0.0, 0.0
        omega, phases, amplitudes, rate_amplitudes = self._arrays
        angle = omega * t_s + phases
        value = float(amplitudes @ np.sin(angle))
        rate = float(rate_amplitudes @ np.cos(angle))
        return window * value, window_rate * value + window * rate


MIN_SLOT_S = 0.8
"""The shortest time given to one bump or step pair (the rise, the hold, the way back and a pause)."""


@dataclass(frozen=True)
class Steps:
    """A sequence of smooth transitions: at start_s[k] the level changes by change[k] over rise_s[k]
    (raised cosine). A bump is a step up and one back down; the changes sum to zero so the plate ends where
    it started."""

    start_s: tuple[float, ...]
    change: tuple[float, ...]
    rise_s: tuple[float, ...]

    def __post_init__(self) -> None:
        if not len(self.start_s) == len(self.change) == len(self.rise_s):
            raise ValueError("every step needs a start, a change and a rise time")
        if any(r <= 0.0 for r in self.rise_s):
            raise ValueError("rise times must be > 0")
        if abs(sum(self.change)) > 1e-12:
            raise ValueError("the steps must return to the starting level")

    @classmethod
    def random(
        cls,
        rng: np.random.Generator,
        duration_s: float,
        size_m: tuple[float, float],
        events: int = 6,
    ) -> Steps:
        """Up to `events` bumps (up and back after 50-250 ms) and step pairs (up or down, held for 0.3-0.6
        of a slot), alternating, one per slot of at least MIN_SLOT_S, at a random time in its slot, each
        20-60 ms in rise, of a size drawn in `size_m`. All are over before duration_s."""
        count = max(1, min(events, int((duration_s - 0.5) / MIN_SLOT_S)))
        slot = (duration_s - 0.5) / count
        starts: list[float] = []
        changes: list[float] = []
        rises: list[float] = []
        for k in range(count):
            t0 = 0.3 + k * slot + float(rng.uniform(0.0, 0.2 * slot))
            size = float(rng.uniform(*size_m)) * (1.0 if rng.random() < 0.6 else -1.0)
            rise, back_rise = (float(r) for r in rng.uniform(0.02, 0.06, size=2))
            hold = float(rng.uniform(0.05, 0.25) if k % 2 == 0 else rng.uniform(0.3, 0.6) * slot)
            starts += [t0, t0 + rise + hold]
            changes += [size, -size]
            rises += [rise, back_rise]
        return cls(tuple(starts), tuple(changes), tuple(rises))

    def motion(self, t_s: float) -> tuple[float, float]:
        value = rate = 0.0
        for start, change, rise in zip(self.start_s, self.change, self.rise_s, strict=True):
            level, level_rate = _raised_cosine((t_s - start) / rise)
            value += change * level
            rate += change * level_rate / rise
        return value, rate


@dataclass(frozen=True)
class Still:
    """No motion (the plate at rest, or the actuator commanded nothing)."""

    def motion(self, t_s: float) -> tuple[float, float]:
        return 0.0, 0.0
