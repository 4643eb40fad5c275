"""The differentiating filter: its bias on a 20 Hz sweep against known derivatives, and settings that follow
the data (noise level, band)."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.signals import choose_filters, kinematics
from estimator.sweep import SweepSettings
from simulators.excitation import sweep_frequency_Hz, sweep_phase_rad

DT = 0.001


def _sweep(noise_m: float, seed: int = 0):
    """x = A·sin(phase(t)) for a 0-20 Hz sweep with its exact velocity and acceleration."""
    sweep = SweepSettings(duration_s=20.0)
    t = np.arange(0, 20.0, DT)
    phase, omega = sweep_phase_rad(sweep, t), 2 * np.pi * sweep_frequency_Hz(sweep, t)
    domega = 2 * np.pi * (sweep.stop_Hz - sweep.start_Hz) / sweep.duration_s
    a = sweep.amplitude_m
    x = a * np.sin(phase)
    v = a * omega * np.cos(phase)
    acc = a * (domega * np.cos(phase) - omega**2 * np.sin(phase))
    rng = np.random.default_rng(seed)
    return t, x + rng.normal(0, noise_m, t.size), v, acc, omega


def _relative_error(estimate: np.ndarray, exact: np.ndarray, window: slice) -> float:
    return float(np.sqrt(np.mean((estimate[window] - exact[window]) ** 2) / np.mean(exact[window] ** 2)))


def test_bias_on_a_20_hz_sweep_without_noise_is_below_a_tenth_of_a_percent() -> None:
    _, x, v, acc, _ = _sweep(noise_m=0.0)
    plate = {"x_r": x + np.random.default_rng(1).normal(0, 5e-6, x.size)}  # the choice needs a noise floor
    cut = choose_filters(plate, DT).kinematics_cutoff_Hz
    k = kinematics(x, cut, DT)
    top = slice(int(17.0 / DT), int(19.5 / DT))  # 17-19.5 Hz: the worst part of the sweep
    velocity_bias = _relative_error(k.velocity_m_s, v, top)
    acceleration_bias = _relative_error(k.acceleration_m_s2, acc, top)
    print(
        f"cutoff {cut:.1f} Hz; bias at 17-19.5 Hz: velocity {100 * velocity_bias:.3f}%, "
        f"acceleration {100 * acceleration_bias:.3f}%"
    )
    assert velocity_bias < 0.001
    assert acceleration_bias < 0.001


def test_with_5_um_noise_the_derivatives_stay_close() -> None:
    _, x, v, acc, _ = _sweep(noise_m=5e-6, seed=3)
    choice = choose_filters({"x_r": x}, DT)
    k = kinematics(x, choice.kinematics_cutoff_Hz, DT)
    band = slice(int(5.0 / DT), int(19.5 / DT))
    assert _relative_error(k.velocity_m_s, v, band) < 0.01
    assert _relative_error(k.acceleration_m_s2, acc, band) < 0.05


@pytest.mark.parametrize("noise_m", [2e-6, 5e-6, 20e-6])
def test_noise_floor_is_estimated_from_the_data(noise_m: float) -> None:
    _, x, *_ = _sweep(noise_m=noise_m, seed=7)
    choice = choose_filters({"x_r": x}, DT)
    assert choice.noise_floor_m == pytest.approx(noise_m, rel=0.15)


def test_cutoffs_follow_the_band_of_the_excitation() -> None:
    """A sweep to 10 Hz gets lower cutoffs than a sweep to 20 Hz: the settings come from the data."""
    rng = np.random.default_rng(0)
    t = np.arange(0, 20.0, DT)
    cutoffs = {}
    for top in (10.0, 20.0):
        sweep = SweepSettings(stop_Hz=top, duration_s=20.0)
        x = 0.004 * np.sin(sweep_phase_rad(sweep, t)) + rng.normal(0, 5e-6, t.size)
        choice = choose_filters({"x_r": x}, DT)
        assert choice.excitation_top_Hz == pytest.approx(top, abs=2.0)
        cutoffs[top] = (choice.equation_cutoff_Hz, choice.kinematics_cutoff_Hz)
    assert cutoffs[10.0][0] < cutoffs[20.0][0]
    assert cutoffs[10.0][1] < cutoffs[20.0][1]
