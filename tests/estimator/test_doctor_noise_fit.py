"""The doctor's noise law fit solves its 2-unknown non-negative least squares without scipy.optimize: the same
solution as scipy.optimize.nnls on random designs, with the constraints binding or not."""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from estimator.doctor.noise import two_column_nnls


def test_two_column_nnls_matches_scipy(hit_rate) -> None:
    rng = np.random.default_rng(7)
    trials, binding, agree = 300, 0, 0
    for _ in range(trials):
        rows = int(rng.integers(3, 60))
        design = rng.normal(size=(rows, 2)) * 10.0 ** rng.uniform(-3, 3, size=2)
        target = rng.normal(size=rows) + design @ rng.uniform(-1.0, 1.0, size=2)
        expected, expected_misfit = nnls(design, target)
        found, misfit = two_column_nnls(design, target)
        binding += bool(np.any(expected == 0.0))
        agree += bool(
            misfit <= expected_misfit * (1 + 1e-9) + 1e-12
            and np.allclose(found, expected, rtol=1e-7, atol=1e-9 * np.max(np.abs(expected), initial=1.0))
            and np.all(found >= 0.0)
        )
    hit_rate(
        "two-column NNLS against scipy.optimize.nnls",
        f"{agree}/{trials} random designs agree; a constraint binds in {binding}",
        agree == trials,
    )
    assert agree == trials
    assert 0.2 * trials < binding < 0.9 * trials  # both kinds of case were drawn


def test_a_zero_column_is_not_a_division_by_zero() -> None:
    design = np.column_stack([np.zeros(5), np.arange(1.0, 6.0)])
    found, misfit = two_column_nnls(design, np.arange(1.0, 6.0))
    assert np.allclose(found, [0.0, 1.0]) and misfit < 1e-12


def test_collinear_columns_put_everything_on_the_first_as_scipy_does() -> None:
    """ρ = 0 makes the AR(1) column a multiple of the white one: the split is not unique, and the noise law
    downstream depends on it, so it follows scipy's choice (the first column alone)."""
    column = np.linspace(1.0, 2.0, 8)
    design = np.column_stack([column, column])
    found, _ = two_column_nnls(design, 3.0 * column)
    expected, _ = nnls(design, 3.0 * column)
    assert np.allclose(found, expected) and np.allclose(found, [3.0, 0.0])
