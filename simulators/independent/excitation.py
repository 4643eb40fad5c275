"""The plate's motion: a linear chirp with smooth (raised-cosine) fade-in and fade-out, then rest.

x_r(t) = A·w(t)·sin(φ(t) + φ0), φ(t) = 2π(f0·t + ½·k·t²) with k = (f1 − f0)/T during the sweep, and the
velocity is its exact derivative A·(w'·sin + w·φ'·cos). The window w rises from 0 to 1 over `fade_s`, holds,
falls back to 0 over `fade_s` at the end of the sweep, and stays 0 during the settling time, so that the
plate starts and ends at rest and both position and velocity are continuous.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Chirp:
    """A plate sweep. amplitude_m zero-to-peak; phase_rad shifts the sine (the second plate of an axle)."""

    start_Hz: float = 0.0
    stop_Hz: float = 20.0
    amplitude_m: float = 0.004
    duration_s: float = 12.0
    fade_s: float = 0.3
    phase_rad: float = 0.0

    def __post_init__(self) -> None:
        if not self.duration_s > 2.0 * self.fade_s:
            raise ValueError("the sweep must be longer than its fade-in and fade-out")

    def _window(self, t_s: float) -> tuple[float, float]:
        """w(t) and dw/dt."""
        if t_s <= 0.0 or t_s >= self.duration_s:
            return 0.0, 0.0
        fade = self.fade_s
        if t_s < fade:
            u = math.pi * t_s / fade
            return 0.5 * (1.0 - math.cos(u)), 0.5 * math.pi / fade * math.sin(u)
        remaining = self.duration_s - t_s
        if remaining < fade:
            u = math.pi * remaining / fade
            return 0.5 * (1.0 - math.cos(u)), -0.5 * math.pi / fade * math.sin(u)
        return 1.0, 0.0

    def _phase(self, t_s: float) -> tuple[float, float]:
        """φ(t) and dφ/dt = 2π·f(t)."""
        rate = (self.stop_Hz - self.start_Hz) / self.duration_s
        phase = 2.0 * math.pi * (self.start_Hz * t_s + 0.5 * rate * t_s * t_s) + self.phase_rad
        return phase, 2.0 * math.pi * (self.start_Hz + rate * t_s)

    def frequency_Hz(self, t_s: float) -> float:
        """The instantaneous frequency during the sweep."""
        return self._phase(min(max(t_s, 0.0), self.duration_s))[1] / (2.0 * math.pi)

    def motion(self, t_s: float) -> tuple[float, float]:
        """Plate position (m) and velocity (m/s) at t_s."""
        window, window_rate = self._window(t_s)
        if window == 0.0 and window_rate == 0.0:
            return 0.0, 0.0
        phase, phase_rate = self._phase(t_s)
        sine, cosine = math.sin(phase), math.cos(phase)
        amplitude = self.amplitude_m
        return amplitude * window * sine, amplitude * (window_rate * sine + window * phase_rate * cosine)
