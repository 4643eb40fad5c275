"""estimator.order_statistics against numpy.median and numpy.quantile: bit for bit on random arrays with fixed
seeds (odd and even lengths, 1-D and along an axis with keepdims, integers, NaNs), and without importing
numpy.ma."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from estimator.order_statistics import median, quantile


def assert_identical(ours: object, reference: object) -> None:
    ours, reference = np.asarray(ours), np.asarray(reference)
    assert ours.shape == reference.shape and ours.dtype == reference.dtype
    assert np.array_equal(ours, reference, equal_nan=True)


@pytest.mark.parametrize("seed", range(20))
def test_equals_numpy_median_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for size in (1, 2, 3, 10, 11, int(rng.integers(12, 5000))):
        values = rng.standard_normal(size) * 10.0 ** rng.uniform(-6, 6)
        assert_identical(median(values), np.median(values))
        assert_identical(
            median(np.abs(values - median(values))), np.median(np.abs(values - np.median(values)))
        )
        assert_identical(median(values, keepdims=True), np.median(values, keepdims=True))
    block = rng.standard_normal((int(rng.integers(1, 6)), int(rng.integers(1, 40))))
    for axis in (0, 1, -1):
        assert_identical(median(block, axis=axis), np.median(block, axis=axis))
        assert_identical(median(block, axis=axis, keepdims=True), np.median(block, axis=axis, keepdims=True))
    integers = rng.integers(-100, 100, int(rng.integers(1, 50)))
    assert_identical(median(integers), np.median(integers))


def test_a_nan_gives_nan_where_numpy_does() -> None:
    rng = np.random.default_rng(7)
    block = rng.standard_normal((4, 9))
    block[1, 3] = np.nan
    assert_identical(median(block, axis=1), np.median(block, axis=1))
    assert np.isnan(median(block))


def test_does_not_import_numpy_ma() -> None:
    code = (
        "import sys, numpy as np; from estimator.order_statistics import median; median(np.arange(5.0)); "
        "print('numpy.ma' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


@pytest.mark.parametrize("seed", range(20))
def test_quantile_equals_numpy_bit_for_bit(seed: int) -> None:
    """Including the velocity grid's quantiles (estimator.damper.velocity_grid: 1% and 99%)."""
    rng = np.random.default_rng(100 + seed)
    for size in (1, 2, 3, 100, int(rng.integers(101, 20000))):
        values = rng.standard_normal(size) * 10.0 ** rng.uniform(-6, 6)
        for q in ([0.01, 0.99], [0.0, 0.25, 0.5, 0.75, 1.0], rng.uniform(0.0, 1.0, 7), 0.3, 0.5):
            assert_identical(quantile(values, q), np.quantile(values, q))
    values = rng.standard_normal((3, 50))
    assert_identical(quantile(values, [0.1, 0.9]), np.quantile(values, [0.1, 0.9]))
    values[1, 7] = np.nan
    assert_identical(quantile(values, [0.1, 0.9]), np.quantile(values, [0.1, 0.9]))
    with pytest.raises(ValueError, match="quantiles"):
        quantile(values, [1.5])
