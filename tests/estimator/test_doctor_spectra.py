"""The doctor's short-time spectrum (estimator.digital_filters.short_time_magnitude) is scipy.signal.stft's,
so that the sweep frequency it reads off the plate is the same without importing scipy.signal in a
diagnosis."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from estimator.digital_filters import short_time_magnitude


@pytest.mark.parametrize("segment", [16, 17, 250, 333, 500])
def test_short_time_magnitude_is_scipys_stft(segment: int) -> None:
    rng = np.random.default_rng(segment)
    rate = 1000.0
    t = np.arange(4321) / rate
    x = 0.004 * np.sin(2 * np.pi * (0.5 + 2.0 * t) * t) + 1e-5 * rng.standard_normal(t.size)
    fft_size = 8 * segment
    expected_f, expected_t, spectrum = signal.stft(
        x, fs=rate, nperseg=segment, noverlap=3 * segment // 4, nfft=fft_size
    )
    frequency, times, magnitude = short_time_magnitude(x, rate, segment, fft_size)
    window_sum = float(np.sum(signal.get_window("hann", segment)))
    np.testing.assert_array_equal(frequency, expected_f)
    np.testing.assert_allclose(times, expected_t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        magnitude / window_sum, np.abs(spectrum), rtol=0, atol=1e-12 * np.abs(spectrum).max()
    )
