"""Robust tanh fit (eq 10): outliers flagged, clean points fitted."""

from __future__ import annotations

import numpy as np
import pytest
from paper_tables import TABLE_2_FORCE_N

from estimator.damper import TanhCurve
from estimator.tanh_fit import fit_tanh


def test_paper_table_2_outlier_is_flagged() -> None:
    """Table 2's constant-stiffness column has 10 821.8 N where about 1 082 N fits; planted in the Maxwell
    column's last point it must be the only one flagged."""
    force = np.array(TABLE_2_FORCE_N["maxwell"])
    force[-1] = 10821.8
    fit = fit_tanh(np.linspace(-1.0, 1.0, 20), force)
    assert fit.outliers == [19]


def test_one_gross_outlier_is_found_in_random_curves(hit_rate) -> None:
    hits = 0
    trials = 30
    for seed in range(trials):
        rng = np.random.default_rng(1000 + seed)
        truth = TanhCurve(
            rng.uniform(50, 800), rng.uniform(200, 1500), rng.uniform(2, 15), rng.uniform(-2, 1)
        )
        v = np.linspace(-0.5, 0.6, 20)
        f = truth.force(v) + rng.normal(0, 3, v.size)
        k = int(rng.integers(v.size))
        f[k] += rng.choice([-1, 1]) * rng.uniform(0.3, 3) * np.max(np.abs(f))
        fit = fit_tanh(v, f)
        hit = fit.outliers == [k]
        hits += hit
    hit_rate(
        "tanh fit: the one planted gross outlier (0.3-3x peak) is exactly what is flagged",
        f"{hits}/{trials} random curves",
        hits >= 0.9 * trials,
    )
    assert hits >= 0.9 * trials


def test_clean_tanh_points_are_recovered_without_outliers() -> None:
    truth = TanhCurve(c_s=300.0, kappa=900.0, mu=6.0, beta=-0.8)
    v = np.linspace(-0.5, 0.6, 20)
    fit = fit_tanh(v, truth.force(v))
    assert fit.outliers == []
    dense = np.linspace(-0.5, 0.6, 200)
    assert np.max(np.abs(fit.curve.force(dense) - truth.force(dense))) < 1.0


def test_bad_points_are_refused() -> None:
    with pytest.raises(ValueError, match="at least 5"):
        fit_tanh(np.arange(3.0), np.arange(3.0))
    with pytest.raises(ValueError, match="finite"):
        fit_tanh(np.array([0, 1, 2, 3, np.nan]), np.arange(5.0))
