"""estimator.doctor's scipy stand-ins for a diagnosis without scipy imports: spline_shift.shift_signal
against scipy.ndimage.shift(order=3, mode="nearest") and distributions.chi_square_survival against
scipy.special.chdtrc, on random draws with fixed seeds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.special import chdtrc

from estimator.distributions import chi_square_survival
from estimator.spline_shift import shift_signal


@pytest.mark.parametrize("seed", range(5))
def test_shift_signal_equals_scipy_ndimage_shift(seed: int) -> None:
    """Random walks and white noise of 5-400 samples, shifts of ±30 samples (beyond the 12-sample edge
    pad, where scipy's nearest-coefficient rule shows): within 1e-14 of the signal's size."""
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(60):
        n = int(rng.integers(5, 400))
        x = np.cumsum(rng.standard_normal(n)) if rng.random() < 0.5 else rng.standard_normal(n)
        x *= 10.0 ** rng.uniform(-6, 0)
        shift = float(rng.uniform(-30.0, 30.0)) if rng.random() < 0.5 else float(rng.uniform(-2.0, 2.0))
        reference = ndimage.shift(x, shift, order=3, mode="nearest")
        worst = max(worst, float(np.max(np.abs(shift_signal(x, shift) - reference)) / np.max(np.abs(x))))
    print(f"\nseed {seed}: worst difference {worst:.1e} of the signal's size")
    assert worst < 1e-14


def test_shift_signal_moves_the_columns_of_a_2d_array() -> None:
    """Columns are signals (the doctor's batched candidate columns): shifted along axis 0 only, each as
    scipy shifts it, and an integer shift inside the record moves samples exactly."""
    rng = np.random.default_rng(7)
    columns = rng.standard_normal((500, 6))
    reference = ndimage.shift(columns, (3.37, 0), order=3, mode="nearest")
    assert np.max(np.abs(shift_signal(columns, 3.37) - reference)) < 1e-13
    assert np.allclose(shift_signal(columns, 4.0)[4:], columns[:-4], rtol=0, atol=1e-13)


def test_chi_square_survival_equals_scipy_chdtrc() -> None:
    """The χ² tail (the whiteness test's and the doctor's Wald and likelihood-ratio tests') at degrees 1-40,
    statistics 0-400 and far out (underflow to 0)."""
    for degrees in (1, 2, 3, 5, 8, 20, 40):
        for statistic in [*np.linspace(0.0, 400.0, 801), 1e4, 1e6]:
            reference = float(chdtrc(degrees, statistic))
            ours = chi_square_survival(float(statistic), degrees)
            assert ours == pytest.approx(reference, rel=1e-12, abs=1e-300)
    with pytest.raises(ValueError, match="positive number of degrees"):
        chi_square_survival(3.0, 0)
