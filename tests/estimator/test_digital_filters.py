"""estimator.digital_filters against scipy.signal, whose definitions it follows: random signals with fixed
seeds, the cutoffs and rates identify uses (and the extremes it may choose), 1-D and several columns along
any axis; equal to 1e-12 relative (scipy.signal stays the reference; identify no longer imports it)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from estimator.digital_filters import (
    analytic_signal,
    butterworth_lowpass_sos,
    first_order_filter,
    sosfiltfilt,
    welch_density,
)

RELATIVE_TOLERANCE = 1e-12
CUTOFFS = [(1000.0, 30.0), (1000.0, 5.0), (1000.0, 400.0), (500.0, 60.0), (2000.0, 5.0), (100.0, 12.5)]


def relative_difference(ours: np.ndarray, reference: np.ndarray) -> float:
    return float(np.max(np.abs(ours - reference)) / np.max(np.abs(reference)))


@pytest.mark.parametrize(("rate_Hz", "cutoff_Hz"), CUTOFFS)
@pytest.mark.parametrize("order", [2, 4, 6])
def test_butterworth_design_equals_scipy(order: int, rate_Hz: float, cutoff_Hz: float) -> None:
    reference = signal.butter(order, cutoff_Hz, btype="low", fs=rate_Hz, output="sos")
    ours = butterworth_lowpass_sos(order, cutoff_Hz, rate_Hz)
    assert ours.shape == reference.shape
    assert np.max(np.abs(ours - reference) / np.maximum(np.abs(reference), 1e-300)) < 1e-13


@pytest.mark.parametrize(("rate_Hz", "cutoff_Hz"), CUTOFFS)
def test_zero_phase_filter_equals_scipy(rate_Hz: float, cutoff_Hz: float) -> None:
    rng = np.random.default_rng(round(cutoff_Hz * 10))
    sos = signal.butter(4, cutoff_Hz, btype="low", fs=rate_Hz, output="sos")
    walk = np.cumsum(rng.standard_normal((12001, 37)), axis=0)  # drifting; more columns than a block
    assert (
        relative_difference(sosfiltfilt(sos, walk), signal.sosfiltfilt(sos, walk, axis=0))
        < RELATIVE_TOLERANCE
    )
    single = walk[:, 1]
    assert relative_difference(sosfiltfilt(sos, single), signal.sosfiltfilt(sos, single)) < RELATIVE_TOLERANCE
    cube = rng.standard_normal((3, 2000, 4))
    assert relative_difference(sosfiltfilt(sos, cube, axis=1), signal.sosfiltfilt(sos, cube, axis=1)) < (
        RELATIVE_TOLERANCE
    )


def test_zero_phase_filter_refuses_a_signal_shorter_than_its_padding() -> None:
    sos = butterworth_lowpass_sos(4, 30.0, 1000.0)
    with pytest.raises(ValueError, match="longer than 15 samples"):
        sosfiltfilt(sos, np.zeros(15))
    with pytest.raises(ValueError, match="cutoff"):
        butterworth_lowpass_sos(4, 600.0, 1000.0)


@pytest.mark.parametrize("theta", [0.0, 0.5, 0.9, 0.97, 0.999])
def test_first_order_filter_equals_lfilter(theta: float) -> None:
    """The Maxwell regressor's recursion (estimator.equations.maxwell_regressor) at ϑ up to 0.999."""
    rng = np.random.default_rng(int(theta * 1000))
    gain, pole = (1.0 - theta) / (1.0 + theta), (3.0 * theta - 1.0) / (1.0 + theta)
    x = rng.standard_normal(12001)
    reference = signal.lfilter([gain, gain], [1.0, -pole], x)
    assert relative_difference(first_order_filter((gain, gain), -pole, x), reference) < RELATIVE_TOLERANCE
    block = rng.standard_normal((2, 3, 700))  # along the last axis, as lfilter
    reference = signal.lfilter([gain, gain], [1.0, -pole], block)
    assert relative_difference(first_order_filter((gain, gain), -pole, block), reference) < RELATIVE_TOLERANCE


@pytest.mark.parametrize(
    ("samples", "segment"), [(12001, 1024), (6001, 512), (300, 256), (100, 100), (257, 256)]
)
def test_welch_density_equals_scipy(samples: int, segment: int) -> None:
    rng = np.random.default_rng(samples)
    x = rng.standard_normal(samples) + np.sin(np.arange(samples) * 0.3)
    frequencies, density = welch_density(x, 1000.0, segment)
    reference_frequencies, reference = signal.welch(x, fs=1000.0, nperseg=segment)
    assert np.array_equal(frequencies, reference_frequencies)
    assert relative_difference(density, reference) < RELATIVE_TOLERANCE


@pytest.mark.parametrize("samples", [12001, 12000, 7])
def test_analytic_signal_equals_hilbert(samples: int) -> None:
    x = np.random.default_rng(samples).standard_normal(samples)
    assert relative_difference(analytic_signal(x), signal.hilbert(x)) < RELATIVE_TOLERANCE
