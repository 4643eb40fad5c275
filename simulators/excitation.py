"""Plate excitation: the sine sweep as a function of time (position, velocity, instantaneous frequency)."""

from __future__ import annotations

import numpy as np

from estimator.sweep import SweepLaw, SweepSettings


def sweep_phase_rad(settings: SweepSettings, t_s: np.ndarray | float) -> np.ndarray:
    """Phase of the sweep at t_s; the frequency holds at stop_Hz after the sweep ends (t > duration_s)."""
    t = np.clip(np.asarray(t_s, dtype=float), 0.0, None)
    f0, f1, T = settings.start_Hz, settings.stop_Hz, settings.duration_s
    tc = np.minimum(t, T)
    if settings.law is SweepLaw.LINEAR:
        k = (f1 - f0) / T
        phase = 2 * np.pi * (f0 * tc + 0.5 * k * tc**2)
    else:
        ratio = f1 / f0
        if abs(ratio - 1.0) < 1e-12:
            phase = 2 * np.pi * f0 * tc
        else:
            phase = 2 * np.pi * f0 * T / np.log(ratio) * (ratio ** (tc / T) - 1.0)
    return phase + 2 * np.pi * f1 * (t - tc)


def sweep_frequency_Hz(settings: SweepSettings, t_s: np.ndarray | float) -> np.ndarray:
    """Instantaneous frequency of the sweep at t_s (stop_Hz after the end)."""
    t = np.clip(np.asarray(t_s, dtype=float), 0.0, settings.duration_s)
    f0, f1, T = settings.start_Hz, settings.stop_Hz, settings.duration_s
    if settings.law is SweepLaw.LINEAR:
        return f0 + (f1 - f0) * t / T
    return f0 * (f1 / f0) ** (t / T)


def sweep_position_m(settings: SweepSettings, t_s: np.ndarray | float) -> np.ndarray:
    """Plate displacement x_r(t) in metres."""
    return settings.amplitude_m * np.sin(sweep_phase_rad(settings, t_s))


def sweep_velocity_m_s(settings: SweepSettings, t_s: np.ndarray | float) -> np.ndarray:
    """Plate velocity dx_r/dt in m/s (exact derivative of sweep_position_m)."""
    omega = 2 * np.pi * sweep_frequency_Hz(settings, t_s)
    return settings.amplitude_m * omega * np.cos(sweep_phase_rad(settings, t_s))


def plate_motion(
    settings: SweepSettings, t_s: np.ndarray | float, ramp_down_s: float = 0.5, phase_offset_rad: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Plate position (m) and velocity (m/s) for a sweep that ends with a linear amplitude ramp-down over
    ramp_down_s (as a controlled stop does) and then rests at zero. phase_offset_rad shifts the sine, e.g.
    for the second plate of an axle bench."""
    t = np.asarray(t_s, dtype=float)
    phase = sweep_phase_rad(settings, t) + phase_offset_rad
    omega = 2 * np.pi * sweep_frequency_Hz(settings, t)
    late = (
        np.clip((t - settings.duration_s) / ramp_down_s, 0.0, 1.0)
        if ramp_down_s > 0
        else ((t > settings.duration_s).astype(float))
    )
    envelope = 1.0 - late
    envelope_rate = np.where((t > settings.duration_s) & (late < 1.0), -1.0 / max(ramp_down_s, 1e-12), 0.0)
    amp = settings.amplitude_m
    position = amp * envelope * np.sin(phase) * (t >= 0)
    velocity = amp * (envelope * omega * np.cos(phase) + envelope_rate * np.sin(phase)) * (t >= 0)
    return position, velocity
