"""The median and the quantiles, computed as numpy.median and numpy.quantile (its default "linear" method)
compute them: the same partition, the same mean of the middle one or two values, the same interpolation,
NaN wherever a NaN is present; equal to the last bit, without importing numpy.ma.

Why: numpy.median's NaN check and numpy.quantile's np.unique read `np.ma`, so the first of them in a
process imports numpy.ma (about 6 ms, 3% of a whole `shockbench identify`, which takes medians in a dozen
places). tests/estimator/test_order_statistics.py checks both against numpy.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def median(values: ArrayLike, axis: int | None = None, keepdims: bool = False) -> np.ndarray:
    """numpy.median(values, axis=axis, keepdims=keepdims) of a float (or integer) array: a numpy scalar for
    axis None without keepdims, else an array. Units: those of `values`."""
    a = np.asarray(values)
    if axis is None:
        flat = a.reshape(-1)
        result = _median_along(flat, 0)
        return result.reshape((1,) * a.ndim) if keepdims else result[()]
    axis = axis % a.ndim
    result = _median_along(a, axis)
    return np.expand_dims(result, axis) if keepdims else result


def _median_along(a: np.ndarray, axis: int) -> np.ndarray:
    size = a.shape[axis]
    if size == 0:
        raise ValueError("the median of an empty array is undefined")
    half = size // 2
    kth = [half - 1, half] if size % 2 == 0 else [half]
    nan_aware = np.issubdtype(a.dtype, np.inexact)
    if nan_aware:
        kth.append(-1)  # the largest last: a NaN, if any, sorts there
    part = np.partition(a, kth, axis=axis)
    middle = slice(half, half + 1) if size % 2 else slice(half - 1, half + 1)
    indexer = tuple(middle if i == axis else slice(None) for i in range(part.ndim))
    result = np.asarray(np.mean(part[indexer], axis=axis))
    if nan_aware:
        last = np.isnan(part.take(-1, axis=axis))
        if np.any(last):
            result = np.where(last, np.nan, result)
    return result


def quantile(values: ArrayLike, q: ArrayLike) -> np.ndarray:
    """numpy.quantile(values, q) (method "linear") over all of `values`: the q-quantiles (q in [0, 1], a
    number or an array of them), of the shape of q. Units: those of `values`."""
    a = np.asarray(values).reshape(-1)
    q = np.asarray(q, dtype=float)
    if a.size == 0:
        raise ValueError("the quantiles of an empty array are undefined")
    if np.any((q < 0.0) | (q > 1.0)):
        raise ValueError("quantiles must lie in [0, 1]")
    count = a.size
    virtual = (count - 1) * np.atleast_1d(q)  # the fractional index in the sorted values
    previous = np.floor(virtual)
    following = previous + 1
    above = virtual >= count - 1
    previous[above], following[above] = -1, -1
    below = virtual < 0
    previous[below], following[below] = 0, 0
    previous, following = previous.astype(np.intp), following.astype(np.intp)
    kth = sorted({0, -1, *previous.ravel().tolist(), *following.ravel().tolist()})
    part = np.partition(a, kth)
    gamma = np.asarray(virtual - previous, dtype=virtual.dtype)
    low, high = part[previous], part[following]
    difference = high - low
    result = np.add(low, difference * gamma)  # numpy's _lerp: from the nearer end
    np.subtract(high, difference * (1 - gamma), out=result, where=gamma >= 0.5, casting="unsafe")
    if np.issubdtype(a.dtype, np.inexact) and np.isnan(part[-1]):
        result = np.full_like(result, np.nan)
    return result.reshape(q.shape)[()]
