"""Resampling one source onto the recording's common grid (1 ms at the bench), with gaps kept as gaps.

Sources run at their own rates and phases: a streaming amplifier samples every millisecond on its own clock
(offset from the grid by a fraction of a period), a polled one whenever the line lets it. The value at a
grid instant g is interpolated from the source's samples around it:

* cubic (4-point Lagrange through the two samples before g and the two after): exact for a cubic, so for a
  1 kHz source the error on a 20 Hz, 4 mm sine is below 0.03 µm, where linear interpolation would be off
  by up to 8 µm (more than the sensor noise) at half a period's offset;
* linear between the two neighbours where one of the outer two is missing or beyond a gap (at the start,
  at the newest data, beside a gap);
* NaN (a gap, marked in the recording, never filled) where the two neighbours are further apart than
  `max_interval_s` (a sample is missing), where a neighbour is NaN (out of range), or where there are no
  samples on one side of g.

`max_interval_s` is set by the recorder from the source's own period: 1.5 periods for a source with its own
clock (one missing sample is a gap), 2.5 typical intervals for a polled source (whose intervals jitter).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

SAME_INSTANT_S = 1e-9
"""A sample this close to a grid instant is taken as at it (sums of float periods differ by ~1e-15 s)."""


class ChannelAligner:
    """Samples of one channel (host seconds, values) in, values on grid instants out."""

    def __init__(self, max_interval_s: float) -> None:
        if not max_interval_s > 0:
            raise ValueError(f"max_interval_s must be positive, got {max_interval_s}")
        self.max_interval_s = float(max_interval_s)
        self._t: FloatArray = np.empty(0)
        self._v: FloatArray = np.empty(0)
        self.out_of_order = 0
        """Samples dropped because they were not later than the newest one already held."""

    def add(self, times_s: FloatArray, values: FloatArray) -> None:
        """Append samples in time order (host seconds); any not later than the newest held is dropped."""
        if times_s.size == 0:
            return
        newest = self._t[-1] if self._t.size else -np.inf
        later = np.concatenate(([times_s[0] > newest], np.diff(times_s) > 0))
        if not np.all(later):
            keep = np.maximum.accumulate(np.concatenate(([newest], times_s)))[:-1] < times_s
            self.out_of_order += int(times_s.size - keep.sum())
            times_s, values = times_s[keep], values[keep]
        self._t = np.concatenate((self._t, times_s))
        self._v = np.concatenate((self._v, values))

    @property
    def newest_s(self) -> float:
        """Time of the newest sample held (-inf when none)."""
        return float(self._t[-1]) if self._t.size else -np.inf

    @property
    def final_until_s(self) -> float:
        """Grid instants up to here get their final value (later samples cannot change it): the
        second-newest sample, as cubic interpolation looks one sample beyond the interval."""
        return float(self._t[-2]) if self._t.size >= 2 else -np.inf

    def values_at(self, grid_s: FloatArray) -> FloatArray:
        """Interpolated values at the grid instants (ascending), NaN where there is a gap (see module)."""
        t, v = self._t, self._v
        out = np.full(grid_s.shape, np.nan)
        n = t.size
        if n == 0 or grid_s.size == 0:
            return out
        i = np.searchsorted(t, grid_s + SAME_INSTANT_S, side="right") - 1  # t[i] <= g < t[i+1]
        exact = (i >= 0) & (np.abs(t[np.clip(i, 0, n - 1)] - grid_s) <= SAME_INSTANT_S)
        out[exact] = v[i[exact]]
        inside = (i >= 0) & (i < n - 1) & ~exact
        if not np.any(inside):
            return out
        idx = i[inside]
        g = grid_s[inside]
        t0, t1 = t[idx], t[idx + 1]
        v0, v1 = v[idx], v[idx + 1]
        ok = (t1 - t0) <= self.max_interval_s
        linear = v0 + (v1 - v0) * (g - t0) / (t1 - t0)
        has_outer = (idx >= 1) & (idx + 2 <= n - 1)
        lo = np.clip(idx - 1, 0, n - 1)
        hi = np.clip(idx + 2, 0, n - 1)
        tm, tp = t[lo], t[hi]
        vm, vp = v[lo], v[hi]
        cubic_ok = (
            has_outer
            & ((t0 - tm) <= self.max_interval_s)
            & ((tp - t1) <= self.max_interval_s)
            & np.isfinite(vm)
            & np.isfinite(vp)
        )
        with np.errstate(invalid="ignore", divide="ignore"):
            cubic = _lagrange4((tm, t0, t1, tp), (vm, v0, v1, vp), g)
        value = np.where(cubic_ok, cubic, linear)
        out[inside] = np.where(ok, value, np.nan)
        return out

    def discard_before(self, time_s: float) -> None:
        """Forget samples no longer needed for grid instants from time_s on (keeps two before it)."""
        keep_from = max(0, int(np.searchsorted(self._t, time_s, side="right")) - 2)
        if keep_from:
            self._t = self._t[keep_from:]
            self._v = self._v[keep_from:]


def _lagrange4(
    nodes: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    values: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    at: FloatArray,
) -> FloatArray:
    """The cubic through four (node, value) pairs per element, evaluated at `at` (all arrays alike)."""
    total = np.zeros_like(at)
    for j in range(4):
        weight = np.ones_like(at)
        for m in range(4):
            if m != j:
                weight *= (at - nodes[m]) / (nodes[j] - nodes[m])
        total += weight * values[j]
    return total
