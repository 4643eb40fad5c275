"""Monotone interpolation in numpy: PCHIP (scipy.interpolate.PchipInterpolator to the last bit) and the
least-squares non-decreasing sequence (isotonic regression). The doctor's plausible truth
(estimator.doctor.expected) makes a damper curve smooth and rising with them; importing scipy.interpolate or
scipy.optimize would cost a diagnosis more than these do (tests/estimator/test_pchip.py and
test_doctor_truth.py check both against scipy)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.damper import PiecewiseLinearCurve


def _end_slope(h0: float, h1: float, m0: float, m1: float) -> float:
    """Moler's one-sided three-point slope at an end, kept shape-preserving (scipy's _edge_case)."""
    d = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    if np.sign(d) != np.sign(m0):
        return 0.0
    if np.sign(m0) != np.sign(m1) and abs(d) > 3.0 * abs(m0):
        return 3.0 * m0
    return d


def _knot_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """PCHIP's slope at every knot (scipy's PchipInterpolator._find_derivatives for a 1-D y)."""
    hk = x[1:] - x[:-1]
    mk = (y[1:] - y[:-1]) / hk
    if y.size == 2:
        return np.array([mk[0], mk[0]])
    smk = np.sign(mk)
    condition = (smk[1:] != smk[:-1]) | (mk[1:] == 0) | (mk[:-1] == 0)
    w1, w2 = 2 * hk[1:] + hk[:-1], hk[1:] + 2 * hk[:-1]
    with np.errstate(divide="ignore", invalid="ignore"):  # where it divides by zero, condition holds
        whmean = (w1 / mk[:-1] + w2 / mk[1:]) / (w1 + w2)
    dk = np.zeros_like(y)
    dk[1:-1][~condition] = 1.0 / whmean[~condition]
    dk[0] = _end_slope(hk[0], hk[1], mk[0], mk[1])
    dk[-1] = _end_slope(hk[-1], hk[-2], mk[-1], mk[-2])
    return dk


@dataclass(frozen=True)
class Pchip:
    """scipy.interpolate.PchipInterpolator(x, y, extrapolate=False) in numpy to the last bit (importing scipy
    would cost a diagnosis more than its one curve): value and slope inside the knots, else NaN."""

    knots_x: np.ndarray
    coefficients: np.ndarray
    """(4, intervals): the cubic's coefficients of (v − x_i)³, ², ¹, ⁰ on each interval (scipy's PPoly.c)."""

    @classmethod
    def through(cls, x: np.ndarray, y: np.ndarray) -> Pchip:
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        if x.ndim != 1 or x.shape != y.shape or x.size < 2 or not np.all(np.diff(x) > 0):
            raise ValueError("PCHIP needs at least two points with strictly increasing x")
        dydx = _knot_slopes(x, y)
        dx = np.diff(x)
        slope = np.diff(y) / dx
        t = (dydx[:-1] + dydx[1:] - 2 * slope) / dx
        return cls(x, np.stack((t / dx, (slope - dydx[:-1]) / dx - t, dydx[:-1], y[:-1])))

    def value(self, v: np.ndarray | float) -> np.ndarray:
        return self._evaluate(v, self.coefficients)

    def slope(self, v: np.ndarray | float) -> np.ndarray:
        """The first derivative (scipy's PPoly.derivative())."""
        return self._evaluate(v, self.coefficients[:-1] * np.array([3.0, 2.0, 1.0])[:, None])

    def _evaluate(self, v: np.ndarray | float, c: np.ndarray) -> np.ndarray:
        v, x = np.asarray(v, dtype=float), self.knots_x
        # [x_i, x_i+1), the last interval closed
        interval = np.clip(np.searchsorted(x, v, side="right") - 1, 0, x.size - 2)
        s = v - x[interval]
        result = np.zeros(v.shape)
        power = np.ones(v.shape)
        for k in range(c.shape[0]):  # scipy's evaluate_poly1: the lowest power first
            result = result + c[c.shape[0] - k - 1, interval] * power
            if k < c.shape[0] - 1:
                power = power * s
        return np.where((v >= x[0]) & (v <= x[-1]), result, np.nan)


def increasing(values: np.ndarray) -> np.ndarray:
    """The non-decreasing sequence nearest to `values` in least squares (isotonic regression by pooling
    adjacent violators: a run that falls is replaced by its mean, merged backwards until none falls). Not
    scipy.optimize.isotonic_regression: importing scipy.optimize costs a diagnosis more than this (as for
    small_nnls); the test checks the two agree."""
    means: list[float] = []
    sizes: list[int] = []
    for value in np.asarray(values, dtype=float):
        means.append(float(value))
        sizes.append(1)
        while len(means) > 1 and means[-2] > means[-1]:
            size = sizes[-2] + sizes[-1]
            means[-2] = (means[-2] * sizes[-2] + means[-1] * sizes[-1]) / size
            sizes[-2] = size
            del means[-1], sizes[-1]
    return np.repeat(means, sizes)


SMOOTH_POINTS = 240  # knots of the dense table of the smooth truth's damper curve


def smooth_curve(curve: PiecewiseLinearCurve) -> PiecewiseLinearCurve:
    """A monotone cubic (PCHIP) through the curve's points made non-decreasing (increasing), linear beyond
    them with the end slopes, tabulated densely over three times the curve's velocity span."""
    lo, hi = float(curve.velocity_m_s[0]), float(curve.velocity_m_s[-1])
    span = hi - lo
    cubic = Pchip.through(curve.velocity_m_s, increasing(curve.force_N))
    inside = np.linspace(lo, hi, SMOOTH_POINTS)
    below = float(cubic.value(lo)) - float(cubic.slope(lo)) * span
    above = float(cubic.value(hi)) + float(cubic.slope(hi)) * span
    grid = np.concatenate([[lo - span], inside, [hi + span]])
    return PiecewiseLinearCurve(grid, np.concatenate([[below], cubic.value(inside), [above]]))
