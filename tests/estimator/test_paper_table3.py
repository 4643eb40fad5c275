"""Issue 15, item 4: the paper's Table 3 against `fit-tanh` of its Table 2.

The paper does not print Table 2's velocities, only that the range between the lowest and the highest
damper velocity was split into 20 points, C_a^10 = 0 N being the one at 0 m/s; so point i sits at
(i − 10)·Δv. Δv is inferred from the paper alone, as the step at which Table 3's three curves pass closest to
their Table 2 points (the misprint left out): each column on its own gives the same step within 2%, which
is what says the grid is right. On that grid every row of our fit lands within 15 N RMS of Table 3's curve,
and the fit describes Table 2's points at least as well as Table 3's curve does.

What brings the rows there is in the fit (estimator/tanh_fit.py): c_s, κ ≥ 0 (the constant-stiffness row's
unconstrained least squares has κ = −1250 N, 41 N from Table 3) and points weighted by the velocity interval
they stand for (the Kelvin-Voigt row's last point, a real upturn, weighs half: 19.0 N with equal weights)."""

from __future__ import annotations

import numpy as np
from paper_tables import MISPRINTED_POINT, TABLE_2_FORCE_N, TABLE_3_TANH

from estimator.damper import TanhCurve
from estimator.tanh_fit import fit_tanh

TABLE_3_TOLERANCE_N = 15.0
"""Issue 15's target: each row within 15 N RMS of Table 3's curve over Table 2's grid."""


def _grid_m_s(step_m_s: float) -> np.ndarray:
    return (np.arange(1, 21) - 10) * step_m_s


def _inliers(column: str) -> np.ndarray:
    keep = np.ones(20, dtype=bool)
    if column == MISPRINTED_POINT[0]:
        keep[MISPRINTED_POINT[1]] = False
    return keep


def _table_3_miss_N(column: str, step_m_s: float) -> float:
    """RMS of Table 3's curve against the column's Table 2 points (misprint left out)."""
    v = _grid_m_s(step_m_s)
    keep = _inliers(column)
    curve = TanhCurve(*TABLE_3_TANH[column])
    return float(np.sqrt(np.mean((curve.force(v[keep]) - np.array(TABLE_2_FORCE_N[column])[keep]) ** 2)))


def _closest_step_m_s(columns: list[str]) -> float:
    """The grid step minimising the summed squared misses of Table 3's curves, by a fine scan."""
    steps = np.linspace(0.05, 0.15, 2001)
    total = [sum(_table_3_miss_N(c, s) ** 2 for c in columns) for s in steps]
    return float(steps[int(np.argmin(total))])


def test_table_2_grid_is_inferred_consistently_from_each_column() -> None:
    steps = [_closest_step_m_s([column]) for column in TABLE_2_FORCE_N]
    assert max(steps) / min(steps) < 1.02, steps
    assert 0.08 < _closest_step_m_s(list(TABLE_2_FORCE_N)) < 0.11


def test_fit_tanh_against_table_3(hit_rate) -> None:
    step = _closest_step_m_s(list(TABLE_2_FORCE_N))
    v = _grid_m_s(step)
    for column, forces in TABLE_2_FORCE_N.items():
        fit = fit_tanh(v, np.array(forces))
        keep = _inliers(column)
        if column == MISPRINTED_POINT[0]:
            assert MISPRINTED_POINT[1] in fit.outliers
        table_3 = TanhCurve(*TABLE_3_TANH[column]).force(v)
        rms_to_table_3 = float(np.sqrt(np.mean((fit.curve.force(v) - table_3) ** 2)))
        fit_miss = float(np.sqrt(np.mean((fit.curve.force(v[keep]) - np.array(forces)[keep]) ** 2)))
        table_3_miss = _table_3_miss_N(column, step)
        hit_rate(
            f"paper Table 3 from Table 2 by fit-tanh, grid step {step:.4f} m/s",
            f"{column}: fit {rms_to_table_3:.1f} N RMS from Table 3's curve; misses Table 2's points by "
            f"{fit_miss:.1f} N RMS, Table 3's curve by {table_3_miss:.1f} N",
            rms_to_table_3 <= TABLE_3_TOLERANCE_N,
        )
        # the fit is the better description of the paper's own points (every point, the misprint aside)
        assert fit_miss <= table_3_miss + 1e-9, column
        assert rms_to_table_3 <= TABLE_3_TOLERANCE_N, column
        assert fit.curve.c_s >= 0 and fit.curve.kappa >= 0, column
