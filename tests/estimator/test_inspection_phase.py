"""estimator.inspection.phase_shift_min_deg on synthetic sweeps of known phase (fixed seeds): a force that
lags the plate by φ at every frequency gives 180° − φ (within 5° below: it is a minimum over windows, and the
analytic signal's edge at the sweep's end pulls it down a few degrees); a sweep that never reaches the minimum
frequency gives NaN."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.digital_filters import analytic_signal
from estimator.inspection import phase_shift_min_deg


def _sweep(rng: np.random.Generator, sample_time_s: float, top_Hz: float) -> np.ndarray:
    t = np.arange(round(12.0 / sample_time_s)) * sample_time_s
    start = rng.uniform(0.5, 2.0)
    return 0.004 * np.sin(2 * np.pi * (start * t + 0.5 * (top_Hz - start) / t[-1] * t**2))


@pytest.mark.parametrize("seed", range(5))
def test_a_constant_lag_gives_180_minus_the_lag(seed: int) -> None:
    rng = np.random.default_rng(seed)
    sample_time_s = float(rng.choice([0.001, 0.002]))
    plate = _sweep(rng, sample_time_s, 20.0)
    lag_deg = rng.uniform(10.0, 170.0)
    lagged = analytic_signal(plate) * np.exp(-1j * np.radians(lag_deg))  # every frequency lags φ
    force = 5e5 * np.real(lagged)
    shift = phase_shift_min_deg(plate, force, sample_time_s)
    assert 180.0 - lag_deg - 5.0 <= shift <= 180.0 - lag_deg + 0.5  # a minimum: the sweep's end pulls it down


def test_a_sweep_below_the_minimum_frequency_gives_nan() -> None:
    plate = _sweep(np.random.default_rng(9), 0.001, 3.0)
    assert np.isnan(phase_shift_min_deg(plate, 1e5 * plate, 0.001, min_frequency_Hz=10.0))
