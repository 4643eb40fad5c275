"""estimator.digital_filters against scipy.signal, whose definitions it follows: random signals with fixed
seeds, the cutoffs and rates identify uses (and the extremes it may choose), 1-D and several columns along
any axis; equal to 1e-12 relative (scipy.signal stays the reference; identify no longer imports it).

Every test runs with both recursions: the compiled one of the extension built ahead of time (built here by
compile_ahead when the tree has none for the present source) and the LAPACK fallback used without it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal
from scipy.linalg import lapack

import estimator.digital_filters as digital_filters
from estimator.damper import hat_basis
from estimator.digital_filters import (
    analytic_signal,
    butterworth_lowpass_sos,
    first_order_filter,
    sosfiltfilt,
    welch_density,
)
from estimator.simulation_kernel import compiled_filters
from service.kernel_build import compile_ahead

RELATIVE_TOLERANCE = 1e-12


@pytest.fixture(scope="module")
def extension():
    """The extension with the compiled filters, built by compile_ahead if missing."""
    assert compile_ahead() == "extension"
    kernels = compiled_filters()
    assert kernels is not None
    return kernels


@pytest.fixture(autouse=True, params=["compiled", "lapack"])
def filters(request, monkeypatch, extension) -> str:
    """Runs the test with the extension's filters, then with numpy and LAPACK's (no extension)."""
    chosen = extension if request.param == "compiled" else None
    monkeypatch.setattr(digital_filters, "compiled_filters", lambda: chosen)
    return request.param


def lapack_recursion(a1: float, a2: float, right: np.ndarray) -> np.ndarray:
    """The reference: y[n] + a1·y[n−1] + a2·y[n−2] = right[n] by LAPACK's banded triangular solve."""
    band = np.empty((3, right.shape[0]))
    band[0], band[1], band[2] = 1.0, a1, a2
    solution, info = lapack.dtbtrs(band, right, uplo="L", trans="N", diag="U")
    assert info == 0
    return solution


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


def test_compiled_recursion_equals_lapack(extension) -> None:
    """The extension's recursion against LAPACK's dtbtrs on 300 random stable second- and first-order
    recursions (poles of radius up to 0.9995), 1-3000 samples, 1-40 columns, column-major or not."""
    rng = np.random.default_rng(15)
    worst = 0.0
    for _ in range(300):
        samples, columns = int(rng.integers(1, 3000)), int(rng.integers(1, 40))
        radius, angle = rng.uniform(0.0, 0.9995), rng.uniform(0.0, np.pi)
        a1, a2 = (-2.0 * radius * np.cos(angle), radius**2) if rng.random() < 0.7 else (-radius, 0.0)
        right = rng.standard_normal((samples, columns)) * rng.uniform(1e-6, 1e6)
        right = np.asfortranarray(right) if rng.random() < 0.8 else right
        reference = lapack_recursion(a1, a2, np.asfortranarray(right))
        extension.recursion(a1, a2, right)
        worst = max(worst, relative_difference(right, reference))
    assert worst < RELATIVE_TOLERANCE


def test_doctor_sized_filtering_same_with_both_paths(monkeypatch, extension) -> None:
    """The doctor's multi-column uses, each with the extension's filters and with LAPACK's: a damper
    basis of 30 s at 500 Hz, 45 columns, low-passed by sosfiltfilt (blocks of 16 columns), and 200 AR(1)
    noise draws of 6000 samples through first_order_filter."""
    rng = np.random.default_rng(2026)
    basis = np.cumsum(rng.standard_normal((15001, 45)), axis=0)
    draws = rng.standard_normal((200, 6000))
    sos = butterworth_lowpass_sos(4, 25.0, 500.0)
    results = {}
    for name, chosen in [("compiled", extension), ("lapack", None)]:
        monkeypatch.setattr(digital_filters, "compiled_filters", lambda chosen=chosen: chosen)
        results[name] = (sosfiltfilt(sos, basis, axis=0), first_order_filter((1.0, 0.0), -0.93, draws))
    for compiled, reference in zip(results["compiled"], results["lapack"], strict=True):
        assert relative_difference(compiled, reference) < RELATIVE_TOLERANCE
    assert relative_difference(results["compiled"][0], signal.sosfiltfilt(sos, basis, axis=0)) < (
        RELATIVE_TOLERANCE
    )


def test_a_column_quiet_for_long_stretches_filters_to_zeros_not_subnormals() -> None:
    """A tent function of one damper knot (estimator.damper.hat_basis) is zero between the sweep's passes
    over its knot; the filter's tail there decays through the subnormal range, where arithmetic is many
    times slower, unless flushed. Both paths give exact zeros there instead, no subnormal anywhere, and
    scipy's values to 1e-12 relative."""
    time_s = np.arange(15001) * 0.002
    velocity = 0.3 * np.sin(2 * np.pi * (0.3 + 0.08 * time_s) * time_s) * np.exp(-time_s / 10)
    grid = np.linspace(-0.4, 0.4, 30)
    basis = np.asfortranarray(hat_basis(velocity, grid))
    sos = butterworth_lowpass_sos(4, 25.0, 500.0)
    reference = signal.sosfiltfilt(sos, basis, axis=0)
    tiny = np.finfo(float).tiny
    subnormal = (reference != 0) & (np.abs(reference) < tiny)
    assert np.count_nonzero(subnormal) > 1000  # the case is real
    ours = sosfiltfilt(sos, basis, axis=0)
    assert np.count_nonzero((ours != 0) & (np.abs(ours) < tiny)) == 0
    assert np.mean(ours[subnormal] == 0.0) > 0.99  # flushed early in each quiet stretch
    assert relative_difference(ours, reference) < RELATIVE_TOLERANCE
