"""The recursive filters of estimator.digital_filters for numba: the zero-phase Butterworth low-pass
(scipy.signal.sosfiltfilt's definition) and the second-order recursion under the first-order filter.

Why compiled: a recursive filter is a per-sample recursion, which numpy cannot vectorise over time; LAPACK's
banded triangular solve does it (digital_filters' fallback) but costs each process the import of
scipy.linalg (0.1-0.3 s, more than a whole identify's filtering), and the numpy steps around it (padding, the
numerator, a copy per section) pass over the data several times. Here each column is padded, filtered
forward and backward through every section, and trimmed in one buffer.

These functions are built ahead of time into the same extension as the output-error kernel
(service/kernel_build.py: `recursion`, `zero_phase`); estimator.simulation_kernel.compiled_filters hands
them to estimator.digital_filters, which uses LAPACK without the extension (it never imports numba: its
import and cache load would cost more than the filtering).

Each value is computed in the order of operations of digital_filters' numpy/LAPACK path (the numerator
((b0·x[n] + b1·x[n−1]) + b2·x[n−2]) plus the initial state on the first two samples, then LAPACK dtbsv's
forward substitution y[n] = (r[n] − a2·y[n−2]) − a1·y[n−1]), so the two paths agree to the last bit
wherever the compiler keeps that order (tests/estimator/test_digital_filters.py asserts 1e-12 relative).

Subnormal numbers. A column that is zero over long stretches (a damper basis's tent function of one
velocity knot) leaves each section's state decaying exponentially through the subnormal range (below
2.2e-308), where every operation takes a slow microcode path on Intel processors (the hat basis of a 30 s,
500 Hz doctor filtered 8× slower than a dense column, and its Gram matrix 15× slower). Every FLUSH_BLOCK
samples, a state below the column's peak times digital_filters.FLUSH_BELOW_PEAK is set to 0; the LAPACK
path sets its output below that floor to 0 after the fact.
"""

from __future__ import annotations

import numba
import numpy as np

from estimator.digital_filters import FLUSH_BELOW_PEAK

FLUSH_BLOCK = 64
"""Samples between the checks of a section's state against its floor (FLUSH_BELOW_PEAK): off the
recursion's critical path, and few enough that no stable section's state falls from the floor to the
subnormal range between two checks."""


@numba.njit(cache=True, error_model="numpy")
def recursion(a1: float, a2: float, right) -> None:
    """In place, every column of right (samples, columns): y[n] + a1·y[n−1] + a2·y[n−2] = right[n], zero
    before n = 0. A column at a time: its samples are contiguous in the column-major arrays the filters
    pass."""
    samples, columns = right.shape
    for column in range(columns):
        if samples > 1:
            right[1, column] = right[1, column] - a1 * right[0, column]
        for n in range(2, samples):
            right[n, column] = (right[n, column] - a2 * right[n - 2, column]) - a1 * right[n - 1, column]


@numba.njit(error_model="numpy", inline="always")
def _section(
    buffer, start: int, step: int, length: int, coefficients, zi0: float, zi1: float, floor: float
) -> None:
    """One second-order section (b0, b1, b2, a1, a2), direct form II transposed from the state
    (zi0, zi1), in place over buffer[start], buffer[start + step], … (length samples; step ±1); a state
    below `floor` after a block of FLUSH_BLOCK samples becomes 0 (module docstring)."""
    b0, b1, b2, a1, a2 = coefficients
    x2 = 0.0  # the input two samples back
    x1 = buffer[start]  # the input one sample back
    y0 = b0 * x1 + zi0
    buffer[start] = y0
    index = start + step
    x0 = buffer[index]
    y1 = ((b0 * x0 + b1 * x1) + zi1) - a1 * y0
    buffer[index] = y1
    x2, x1 = x1, x0
    done = 2
    while done < length:
        block = min(FLUSH_BLOCK, length - done)
        for _ in range(block):
            index += step
            x0 = buffer[index]
            y2 = (((b0 * x0 + b1 * x1) + b2 * x2) - a2 * y0) - a1 * y1
            buffer[index] = y2
            x2, x1 = x1, x0
            y0, y1 = y1, y2
        done += block
        if max(abs(y0), abs(y1)) < floor:
            y0 = y1 = 0.0


@numba.njit(error_model="numpy", inline="always")
def _two_sections(
    buffer, start: int, step: int, length: int, first, z0, z1, second, w0, w1, floor: float
) -> None:
    """Two sections in cascade (`first` from the state (z0, z1), then `second` from (w0, w1)), in one pass:
    the same values as _section twice, but the two recursions overlap in the processor (each is bound by
    its own multiply-subtract latency), which makes the pass about twice as fast."""
    b0, b1, b2, a1, a2 = first
    c0, c1, c2, d1, d2 = second
    index = start
    x1 = buffer[index]
    u0 = b0 * x1 + z0  # the first section's output, the second's input
    v0 = c0 * u0 + w0
    buffer[index] = v0
    index += step
    x0 = buffer[index]
    u1 = ((b0 * x0 + b1 * x1) + z1) - a1 * u0
    v1 = ((c0 * u1 + c1 * u0) + w1) - d1 * v0
    buffer[index] = v1
    x2, x1 = x1, x0
    done = 2
    while done < length:
        block = min(FLUSH_BLOCK, length - done)
        for _ in range(block):
            index += step
            x0 = buffer[index]
            u2 = (((b0 * x0 + b1 * x1) + b2 * x2) - a2 * u0) - a1 * u1
            v2 = (((c0 * u2 + c1 * u1) + c2 * u0) - d2 * v0) - d1 * v1
            buffer[index] = v2
            x2, x1 = x1, x0
            u0, u1 = u1, u2
            v0, v1 = v1, v2
        done += block
        if max(abs(u0), abs(u1), abs(v0), abs(v1)) < floor:
            u0 = u1 = v0 = v1 = 0.0


@numba.njit(error_model="numpy", inline="always")
def _cascade(
    buffer, start: int, step: int, length: int, coefficients, zi, scale: float, floor: float
) -> None:
    """Every section in turn (two at a time), from the states zi·scale, in place along the buffer; states
    below `floor` flushed to 0."""
    sections = len(coefficients)
    k = 0
    while k + 1 < sections:
        _two_sections(
            buffer, start, step, length,
            coefficients[k], zi[k, 0] * scale, zi[k, 1] * scale,
            coefficients[k + 1], zi[k + 1, 0] * scale, zi[k + 1, 1] * scale, floor,
        )  # fmt: skip
        k += 2
    if k < sections:
        _section(buffer, start, step, length, coefficients[k], zi[k, 0] * scale, zi[k, 1] * scale, floor)


@numba.njit(cache=True, error_model="numpy")
def zero_phase(sos, zi, edge: int, x, out) -> None:
    """scipy.signal.sosfiltfilt of every column of x (samples, columns) into out (samples, columns):
    odd extension by `edge` samples at each end, forward then backward through the sections sos
    (sections, 5: b0, b1, b2, a1, a2 with a0 = 1) from the steady states zi (sections, 2) times the first
    sample each way, trimmed back to `samples`."""
    samples, columns = x.shape
    length = samples + 2 * edge
    buffer = np.empty(length)
    coefficients = [(sos[k, 0], sos[k, 1], sos[k, 2], sos[k, 3], sos[k, 4]) for k in range(sos.shape[0])]
    for column in range(columns):
        first, last = x[0, column], x[samples - 1, column]
        peak = 0.0  # of the padded column, found as it is copied in
        for i in range(edge):
            buffer[i] = 2.0 * first - x[edge - i, column]
            buffer[edge + samples + i] = 2.0 * last - x[samples - 2 - i, column]
            peak = max(peak, abs(buffer[i]), abs(buffer[edge + samples + i]))
        for i in range(samples):
            buffer[edge + i] = x[i, column]
            peak = max(peak, abs(buffer[edge + i]))
        floor = peak * FLUSH_BELOW_PEAK
        _cascade(buffer, 0, 1, length, coefficients, zi, buffer[0], floor)
        _cascade(buffer, length - 1, -1, length, coefficients, zi, buffer[length - 1], floor)
        for i in range(samples):
            out[i, column] = buffer[edge + i]


RECURSION_SIGNATURE = "void(f8, f8, f8[:, :])"
"""recursion's argument types, as the extension exports it (any memory layout)."""
ZERO_PHASE_SIGNATURE = "void(f8[:, :], f8[:, :], i8, f8[:, :], f8[:, :])"
"""zero_phase's argument types, as the extension exports it (any memory layout)."""
