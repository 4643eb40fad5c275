"""estimator.monotone.Pchip against scipy.interpolate.PchipInterpolator, which it replaces: bit for
bit on random curves with fixed seeds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import PchipInterpolator

from estimator.monotone import Pchip


@pytest.mark.parametrize("seed", range(10))
def test_pchip_equals_scipy_bit_for_bit(seed: int) -> None:
    """Damper-like monotone curves and wiggly ones, 2-40 knots; values and slopes at the knots, between
    them and outside (NaN, as extrapolate=False)."""
    rng = np.random.default_rng(seed)
    for _ in range(30):
        x = np.unique(rng.uniform(-2.0, 2.0, int(rng.integers(2, 40))))
        if x.size < 2:
            continue
        if rng.random() < 0.7:
            y = np.cumsum(rng.uniform(-0.5, 2.0, x.size)) * 1000.0
        else:
            y = rng.standard_normal(x.size) * 100.0
        reference, ours = PchipInterpolator(x, y, extrapolate=False), Pchip.through(x, y)
        v = np.concatenate([np.linspace(x[0], x[-1], 240), x, [x[0] - 1.0, x[-1] + 1.0]])
        assert np.array_equal(ours.value(v), reference(v), equal_nan=True)
        assert np.array_equal(ours.slope(v), reference.derivative()(v), equal_nan=True)
        assert float(ours.value(x[-1])) == float(reference(x[-1]))
