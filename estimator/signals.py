"""From measured displacements to velocities and accelerations, with filter settings chosen from the data.

Only displacements are measured. Two zero-phase Butterworth low-passes (4th order, run forward and
backward; estimator.digital_filters, scipy.signal's definitions without its import cost) are used:

- the *kinematics* filter (cutoff `kinematics_cutoff_Hz`) before central differences gives the velocities
  used inside nonlinear terms (the damper curve's velocity, the tyre deflection rate), and the states used for
  output error and inspection figures. Its cutoff sits above the band where the signals stand out of the
  sensor noise, so it does not bend the response.
- the *equation* filter (cutoff `equation_cutoff_Hz`) is applied to every column of the equations of motion
  alike (accelerations, positions and each damper basis function of the velocity). The equations are linear
  in those columns, so they hold exactly after filtering while the noise amplified by double
  differentiation is cut, and the harmonics that a nonlinear damper generates are treated the same way in
  the acceleration as in the damper force (no bias from filtering one and not the other).

How the cutoffs are chosen from the data: the noise floor is the median Welch power density in the top 40% of
the band below Nyquist (laser noise is white there; the vehicle has no response); the signal band edge is
the highest frequency where any channel's density is `SNR_DB` above that floor. The kinematics cutoff is
KINEMATICS_CUTOFF_RATIO × the band edge; the equation cutoff is
EQUATION_CUTOFF_RATIO × the excitation's top frequency (found from the plate
channels' spectrum). Both are clipped to [5 Hz, 0.4 × sample rate]. Measured on a 0-20 Hz sweep (test
test_signals.py): velocity and acceleration bias at 17-19.5 Hz about 0.03%.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from estimator.digital_filters import (
    butterworth_lowpass_sos,
    short_time_magnitude,
    sosfiltfilt,
    welch_density,
)
from estimator.order_statistics import median

SNR_DB = 20.0
KINEMATICS_CUTOFF_RATIO = 2.0
EQUATION_CUTOFF_RATIO = 1.5
FILTER_ORDER = 4
MIN_CUTOFF_HZ = 5.0
MAX_CUTOFF_FRACTION_OF_RATE = 0.4


@dataclass(frozen=True)
class FilterChoice:
    """Filter settings and the evidence they were chosen from."""

    sample_time_s: float
    noise_floor_m: float
    """Estimated white-noise standard deviation of the displacement channels (m)."""
    band_edge_Hz: float
    excitation_top_Hz: float
    kinematics_cutoff_Hz: float
    equation_cutoff_Hz: float


def _welch(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    nperseg = int(min(x.size, max(256, 2 ** int(np.log2(fs)))))  # ~1 s segments: 1 Hz resolution
    return welch_density(x - np.mean(x), fs, nperseg)


def choose_filters(channels: dict[str, np.ndarray], sample_time_s: float) -> FilterChoice:
    """Pick both cutoffs from the spectra of the displacement channels (see module docstring)."""
    fs = 1.0 / sample_time_s
    hi_limit = MAX_CUTOFF_FRACTION_OF_RATE * fs
    floors, edges, plate_tops = [], [], []
    for name, x in channels.items():
        f, p = _welch(x, fs)
        top = f >= 0.6 * f[-1]
        floor = float(median(p[top])) if np.any(top) else float(np.min(p))
        floors.append(floor)
        above = np.nonzero(p > floor * 10 ** (SNR_DB / 10))[0]
        edge = float(f[above[-1]]) if above.size else MIN_CUTOFF_HZ
        edges.append(edge)
        if name.startswith("x_r"):
            # the excitation's top: where the plate's density falls 20 dB under its peak, searched upwards
            strong = np.nonzero(p > p.max() * 1e-2)[0]
            plate_tops.append(float(f[strong[-1]]) if strong.size else edge)
    noise_density = float(median(floors))  # m²/Hz, one-sided
    band_edge = float(max(edges))
    excitation_top = float(max(plate_tops)) if plate_tops else band_edge
    return FilterChoice(
        sample_time_s=sample_time_s,
        noise_floor_m=float(np.sqrt(noise_density * fs / 2)),
        band_edge_Hz=band_edge,
        excitation_top_Hz=excitation_top,
        kinematics_cutoff_Hz=float(np.clip(KINEMATICS_CUTOFF_RATIO * band_edge, MIN_CUTOFF_HZ, hi_limit)),
        equation_cutoff_Hz=float(np.clip(EQUATION_CUTOFF_RATIO * excitation_top, MIN_CUTOFF_HZ, hi_limit)),
    )


@lru_cache(maxsize=64)
def _butterworth(cutoff_Hz: float, sample_time_s: float) -> np.ndarray:
    """The low-pass's second-order sections, designed once per cutoff and sample time."""
    return butterworth_lowpass_sos(FILTER_ORDER, cutoff_Hz, 1.0 / sample_time_s)


def lowpass(x: np.ndarray, cutoff_Hz: float, sample_time_s: float, axis: int = 0) -> np.ndarray:
    """Zero-phase Butterworth low-pass (FILTER_ORDER, forward and backward)."""
    return sosfiltfilt(_butterworth(float(cutoff_Hz), float(sample_time_s)), x, axis=axis)


def derivative(x: np.ndarray, sample_time_s: float, axis: int = 0) -> np.ndarray:
    """Fourth-order central differences, (−x[i+2] + 8·x[i+1] − 8·x[i−1] + x[i−2]) / 12Δt: at 20 Hz and
    1 kHz the gain error is 8·10⁻⁶ (second-order differences lose 0.26%). Second order at the two samples
    next to each end, one-sided at the ends."""
    x = np.moveaxis(np.asarray(x, dtype=float), axis, 0)
    out = np.gradient(x, sample_time_s, axis=0)
    if x.shape[0] >= 5:
        out[2:-2] = (-x[4:] + 8.0 * x[3:-1] - 8.0 * x[1:-3] + x[:-4]) / (12.0 * sample_time_s)
    return np.moveaxis(out, 0, axis)


@dataclass(frozen=True)
class Kinematics:
    """Position, velocity and acceleration of one channel after a low-pass of the given cutoff."""

    position_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray


def kinematics(x: np.ndarray, cutoff_Hz: float, sample_time_s: float) -> Kinematics:
    """Low-pass, then differentiate twice (fourth-order central differences)."""
    position = lowpass(x, cutoff_Hz, sample_time_s)
    velocity = derivative(position, sample_time_s)
    return Kinematics(position, velocity, derivative(velocity, sample_time_s))


INITIAL_WINDOW_S = 0.2
"""Longest stretch at the start of a recording a quadratic is fitted to for the initial state."""


def initial_state(x_m: np.ndarray, sample_time_s: float, noise_m: float) -> tuple[float, float]:
    """Position (m) and velocity (m/s) of a channel at its first sample: a quadratic fitted to the longest
    stretch from the start (up to INITIAL_WINDOW_S, halved until it fits within twice the noise). The
    low-passed kinematics are least reliable at the very first sample (the filter's edge), and a wrong
    initial velocity sets the body ringing for the first second of a simulation. Every simulation from a
    measured plate starts so (estimator.output_error for identify and validate, the model doctor)."""
    window = max(8, round(INITIAL_WINDOW_S / sample_time_s))
    while True:
        t = np.arange(min(window, x_m.size)) * sample_time_s
        coefficients = np.polyfit(t, x_m[: t.size], 2)
        misfit = float(np.sqrt(np.mean((np.polyval(coefficients, t) - x_m[: t.size]) ** 2)))
        if misfit <= 2.0 * noise_m or window <= 8:
            return float(coefficients[2]), float(coefficients[1])
        window //= 2


SWEEP_WINDOW_S = 0.5  # short-time spectrum window for the sweep frequency
REST_FRACTION = 0.1
"""Where the plate's amplitude is below this fraction of its largest, the plate rests (no sweep frequency)."""


def sweep_frequency_Hz(plate_m: np.ndarray, sample_time_s: float) -> np.ndarray:
    """The sweep's instantaneous frequency at every sample (NaN where the plate rests)."""
    rate = 1.0 / sample_time_s
    window = max(16, round(SWEEP_WINDOW_S * rate))
    freqs, times, magnitude = short_time_magnitude(plate_m - np.mean(plate_m), rate, window, 8 * window)
    peak = freqs[np.argmax(magnitude, axis=0)]
    amplitude = magnitude.max(axis=0)
    peak = np.where(amplitude >= REST_FRACTION * amplitude.max(), peak, np.nan)
    t = np.arange(plate_m.size) * sample_time_s
    inside = np.isfinite(peak)
    if not np.any(inside):
        return np.full(plate_m.size, np.nan)
    frequency = np.interp(t, times[inside], peak[inside])
    resting = np.interp(t, times, (~inside).astype(float)) > 0.5
    return np.where(resting, np.nan, frequency)
