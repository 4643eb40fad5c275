"""The few signal-processing routines identify needs, in numpy and LAPACK: the Butterworth low-pass design
(second-order sections), zero-phase filtering forward and backward, a first-order recursive filter, Welch's
power density, a short-time spectrum's magnitude and the analytic signal.

Why not scipy.signal: importing it costs 1-2 s on this project's machines (it imports scipy.stats,
scipy.interpolate and scipy.optimize, and rewrites the docstrings of some hundred functions at import),
several times identify's own work, and every `shockbench identify` is a fresh process. These functions
follow scipy.signal's definitions step by step (butter → zpk2sos with 'nearest' pairing, sosfiltfilt with
odd padding and sosfilt_zi initial conditions, lfilter, welch with a periodic Hann window, half overlap and
constant detrend, hilbert); tests/estimator/test_digital_filters.py checks them against scipy.signal to
rounding (1e-12 relative). The recursive filters run compiled: in the extension built ahead of time with
the output-error kernel (estimator.simulation_kernel.compiled_filters, source in
estimator/filter_kernel_numba.py) when it is built, else in numpy around LAPACK's banded triangular solve
(dtbtrs: a recursion y[n] + a1·y[n−1] + a2·y[n−2] = r[n] is that lower-triangular banded system, solved by
forward substitution). The extension spares identify the import of scipy.linalg (0.1-0.3 s, a fifth of a
whole identify) and filters a column in one pass; LAPACK stays the fallback rather than numba's just-in-time
compile, whose import and cache load cost more. Both paths compute each value in the same order of
operations.
"""

from __future__ import annotations

import math

import numpy as np

from estimator.simulation_kernel import compiled_filters

FLUSH_BELOW_PEAK = 2.0**-100
"""Filtered values below a column's peak times this (about 1e-30) are set to 0: 30 orders of magnitude
below anything the column adds to a sum (float64 resolves 16), and far above the subnormal range their
exponential decay would otherwise reach and stay in, where arithmetic is up to 100× slower
(estimator/filter_kernel_numba.py)."""
BLOCK_COLUMNS = 16
"""sosfiltfilt filters this many columns at once: its temporaries (a few copies of a block) stay small
beside the input and output, whatever the number of columns (the doctor filters hundreds)."""


def butterworth_lowpass_sos(order: int, cutoff_Hz: float, sample_rate_Hz: float) -> np.ndarray:
    """scipy.signal.butter(order, cutoff_Hz, btype="low", fs=sample_rate_Hz, output="sos") for an even
    order: (order/2, 6) rows [b0, b1, b2, 1, a1, a2], the gain in the first section, the pole pair nearest
    the unit circle in the last."""
    if order % 2 or order <= 0:
        raise ValueError("the Butterworth order must be even and positive")
    normalized = 2.0 * cutoff_Hz / sample_rate_Hz
    if not 0.0 < normalized < 1.0:
        raise ValueError(f"the cutoff {cutoff_Hz} Hz must lie between 0 and half the rate {sample_rate_Hz}")
    warped = 4.0 * math.tan(math.pi * normalized / 2.0)  # pre-warped, scipy's fs = 2 convention
    analog = warped * -np.exp(1j * np.pi * np.arange(-order + 1, order, 2) / (2 * order))
    poles = (4.0 + analog) / (4.0 - analog)  # bilinear transform; the zeros all go to -1
    gain = float(warped**order * np.real(1.0 / np.prod(4.0 - analog)))
    upper = poles[poles.imag > 0]  # one of each conjugate pair
    upper = upper[np.argsort(-np.abs(1.0 - np.abs(upper)), kind="stable")]  # farthest from the circle first
    sos = np.zeros((order // 2, 6))
    sos[:, :3] = (1.0, 2.0, 1.0)
    sos[:, 3] = 1.0
    sos[:, 4] = -2.0 * upper.real
    sos[:, 5] = (upper * upper.conj()).real
    sos[0, :3] *= gain
    return sos


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """scipy.signal.sosfilt_zi: each section's direct-form II transposed state, (sections, 2), for a unit
    step's steady state."""
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for index, (b0, b1, b2, a0, a1, a2) in enumerate(sos):
        b = np.array([b0, b1, b2]) / a0
        a = np.array([1.0, a1 / a0, a2 / a0])
        i_minus_a = np.array([[1.0 + a[1], -1.0], [a[2], 1.0]])  # I − companion(a)ᵀ
        zi[index] = scale * np.linalg.solve(i_minus_a, b[1:] - a[1:] * b[0])
        scale *= b.sum() / a.sum()
    return zi


def _recursion(a1: float, a2: float, right: np.ndarray) -> np.ndarray:
    """y with y[n] + a1·y[n−1] + a2·y[n−2] = right[n] (zero before n = 0), every column of `right` (n, m),
    a float array that this overwrites (column-major: each column's samples contiguous). Compiled
    (estimator.simulation_kernel's extension) when it is built, else LAPACK's dtbtrs."""
    kernels = compiled_filters()
    if kernels is not None:
        kernels.recursion(a1, a2, right)
        return right
    from scipy.linalg import lapack  # about 0.1-0.3 s to import: only without the extension

    samples = right.shape[0]
    band = np.empty((3, samples))
    band[0], band[1], band[2] = 1.0, a1, a2
    solution, info = lapack.dtbtrs(band, right, uplo="L", trans="N", diag="U", overwrite_b=1)
    if info != 0:
        raise ValueError(f"LAPACK dtbtrs failed (info {info})")
    return solution


def _sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """scipy.signal.sosfilt along axis 0 of x (n, m), from the states zi (sections, 2, m)."""
    y = x
    for (b0, b1, b2, a0, a1, a2), state in zip(sos / sos[:, 3:4], zi, strict=True):
        del a0
        right = b0 * y  # column-major like y: the recursion solves it in place
        right[1:] += b1 * y[:-1]
        right[2:] += b2 * y[:-2]
        right[0] += state[0]  # direct form II transposed: y0 = b0·x0 + z0, y1 = … − a1·y0 + z1
        right[1] += state[1]
        y = _recursion(a1, a2, right)
    return y


def sosfiltfilt(sos: np.ndarray, x: np.ndarray, axis: int = 0) -> np.ndarray:
    """scipy.signal.sosfiltfilt(sos, x, axis) with its defaults: odd extension by 3·(2·sections + 1)
    samples at each end (less the sections' trailing zero coefficients), forward then backward from the
    steady state of each end."""
    x = np.moveaxis(np.asarray(x, dtype=float), axis, 0)
    shape = x.shape
    flat = x.reshape(shape[0], -1)
    taps = 2 * sos.shape[0] + 1 - min(int(np.sum(sos[:, 2] == 0)), int(np.sum(sos[:, 5] == 0)))
    edge = 3 * taps
    if flat.shape[0] <= edge:
        raise ValueError(f"the signal must be longer than {edge} samples to be filtered")
    out = np.empty(flat.shape, order="F" if flat.flags.f_contiguous else "C")  # the kernel's writes
    kernels = compiled_filters()  # then run along memory like its reads (a column-major basis: 30% faster)
    if kernels is not None:  # every column padded, filtered both ways and trimmed in one compiled pass
        normalized = sos / sos[:, 3:4]
        kernels.zero_phase(
            np.ascontiguousarray(normalized[:, [0, 1, 2, 4, 5]]), sosfilt_zi(sos), edge, flat, out
        )
        return np.moveaxis(out.reshape(shape), 0, axis)
    zi = sosfilt_zi(sos)[:, :, None]
    for first in range(0, flat.shape[1], BLOCK_COLUMNS):  # a block at a time: the temporaries stay small
        block = flat[:, first : first + BLOCK_COLUMNS]
        extended = np.asfortranarray(
            np.concatenate(
                [2.0 * block[:1] - block[edge:0:-1], block, 2.0 * block[-1:] - block[-2 : -edge - 2 : -1]]
            )
        )  # column-major: each column's samples contiguous, as LAPACK takes them
        forward = _sosfilt(sos, extended, zi * extended[0])
        del extended
        backward = _sosfilt(sos, forward[::-1], zi * forward[-1])
        out[:, first : first + BLOCK_COLUMNS] = backward[::-1][edge:-edge]
    floor = np.max(np.abs(flat), axis=0, initial=0.0) * FLUSH_BELOW_PEAK
    out[np.abs(out) < floor] = 0.0  # the compiled path's flush, after the fact
    return np.moveaxis(out.reshape(shape), 0, axis)


def first_order_filter(b: tuple[float, float], a1: float, x: np.ndarray) -> np.ndarray:
    """scipy.signal.lfilter([b0, b1], [1, a1], x) along the last axis, from rest:
    y[n] = b0·x[n] + b1·x[n−1] − a1·y[n−1]."""
    x = np.moveaxis(np.asarray(x, dtype=float), -1, 0)
    flat = x.reshape(x.shape[0], -1)
    right = np.asfortranarray(b[0] * flat)
    right[1:] += b[1] * flat[:-1]
    return np.moveaxis(_recursion(a1, 0.0, right).reshape(x.shape), 0, -1)


def welch_density(x: np.ndarray, sample_rate_Hz: float, segment: int) -> tuple[np.ndarray, np.ndarray]:
    """scipy.signal.welch(x, fs, nperseg=segment): frequencies and one-sided power density of a 1-D x,
    periodic Hann window, half overlap, each segment's mean removed, the segments' densities averaged."""
    x = np.asarray(x, dtype=float)
    segment = min(segment, x.size)
    step = segment - segment // 2
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(segment) / segment)
    count = (x.size - segment // 2) // step
    starts = np.arange(count) * step
    pieces = x[starts[:, None] + np.arange(segment)]
    pieces = pieces - pieces.mean(axis=1, keepdims=True)
    spectra = np.fft.rfft(window * pieces, axis=1)
    density = (spectra.real**2 + spectra.imag**2) / (sample_rate_Hz * np.sum(window * window))
    if segment % 2:
        density[:, 1:] *= 2.0
    else:
        density[:, 1:-1] *= 2.0
    return np.fft.rfftfreq(segment, 1.0 / sample_rate_Hz), density.mean(axis=0)


def analytic_signal(x: np.ndarray) -> np.ndarray:
    """scipy.signal.hilbert(x) of a 1-D x: x + j·(its Hilbert transform), by the FFT."""
    x = np.asarray(x, dtype=float)
    size = x.size
    weights = np.zeros(size)
    weights[0] = 1.0
    if size % 2 == 0:
        weights[size // 2] = 1.0
        weights[1 : size // 2] = 2.0
    else:
        weights[1 : (size + 1) // 2] = 2.0
    return np.fft.ifft(np.fft.fft(x) * weights)


def short_time_magnitude(
    x: np.ndarray, sample_rate_Hz: float, segment: int, fft_size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies, segment centre times and |STFT| (frequencies, segments) as scipy.signal.stft(x, fs,
    nperseg=segment, noverlap=3·segment//4, nfft=fft_size) has them up to its scale 1/Σwindow, in numpy
    (importing scipy.signal costs a diagnosis 1-2 s): periodic Hann window, segment//2 zeros either end."""
    step = segment - 3 * segment // 4
    half = segment // 2
    padded = np.concatenate([np.zeros(half), np.asarray(x, dtype=float), np.zeros(half)])
    padded = np.concatenate([padded, np.zeros((-(padded.size - segment) % step) % segment)])
    starts = np.arange(0, padded.size - segment + 1, step)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(segment) / segment)
    spectrum = np.fft.rfft(window * padded[starts[:, None] + np.arange(segment)], n=fft_size, axis=1)
    times = starts / sample_rate_Hz  # the segment centres, less the leading zeros
    return np.fft.rfftfreq(fft_size, 1.0 / sample_rate_Hz), times, np.abs(spectrum).T
