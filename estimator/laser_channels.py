"""What a laser channel does to the displacement it measures, and how it is undone: the channel model
validate applies around a simulation (estimator.validation) and the model doctor fits (estimator.doctor).

A channel reads y = (1 + ε)·(H_delay·H_lag·H_average)(x) + offset of the true displacement x:
- H_average, the amplifier's averaging (the ZX amplifier's averaging setting): the mean of x over the
  last T seconds, y(t) = (1/T)·∫ x over [t − T, t];
- H_lag, a first-order lag of time constant τ: τ·ẏ + y = x;
- H_delay, a pure delay D (the channel's clock or transmission);
- the gain error ε (a wrong head range or calibration) and the zero error (offset).
The filters are linear and time-invariant, so their order does not matter in theory; distort applies them
in the order above, each from rest at the signal's first value (as a sensor that was on before the record).

distort, the forward model, causal and as a real amplifier does it, for a signal linear between samples
(the only assumption, the same for the lag and the average):
- the average integrates the piecewise-linear signal exactly over a window of any length, not only whole
  samples (a cumulative trapezoid integral and the part-sample at the window's start); for a whole-sample
  window it is the mean of the trapezoid rule, taps [½, 1, …, 1, ½]/N;
- the lag is the exact discretisation of τ·ẏ + y = x for an input linear between samples (step h,
  a = e^(−h/τ), γ = (τ/h)(1 − a)): y[n] = a·y[n−1] + (1 − γ)·x[n] + (γ − a)·x[n−1]. Not the bilinear
  transform: that is exact for no input, warps frequency and, for τ < h/2, has a negative pole that rings
  at the Nyquist rate; this one is exact for the signal model the average uses too, its pole is in (0, 1)
  and it is what the foreign test world's amplifier does (simulators/foreign/sensors.py);
- the delay is the sub-sample cubic-spline shift (estimator.spline_shift).

correct, the inverse, in the frequency domain: the measured signal less its offset, over (1 + ε), is
extended to damp its ends (below) and divided by the discrete frequency response of the lag and average
(those of distort exactly) and of the delay (e^(−iωD), which the spline shift follows to 2e-4 up to 40 Hz
at 500 Hz), all three in one division. The rule where the response is small (the average's zeros, the
lag's roll-off): the inverse is G = 1/H where |H| ≥ MIN_INVERTED_GAIN and conj(H)/MIN_INVERTED_GAIN²
elsewhere. So correct(distort(x)) is x through a zero-phase filter of gain min(1, |H|²/MIN_INVERTED_GAIN²):
exact wherever the sensor keeps at least a quarter of a frequency, rolled off smoothly (no jump) where it
keeps less, and the noise never amplified more than 1/MIN_INVERTED_GAIN. A quarter keeps the excitation
band (0-20 Hz) exact for the slowest sensor the tests try (a 10 ms lag with a 20 ms average keeps 0.47 at
20 Hz); the equations low-pass their signals at a few tens of Hz, below where the rule acts for most sensors.

The extension: the line through the first and last samples is taken out, and the rest (zero at both ends)
is extended by its point reflection about the last sample, to 2n − 2 samples. Periodically repeated, as
the FFT sees it, that signal is continuous in value and slope at both ends (reflect-padding keeps the value
only, so an inverted lag would turn the slope's jump into a step); the line comes back advanced by the
filters' group delay D + τ + T/2, which is exactly what the inverse does to a line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from estimator.digital_filters import first_order_filter
from estimator.errors import InvalidValueError
from estimator.recording import Recording
from estimator.spline_shift import shift_signal

MIN_INVERTED_GAIN = 0.25
"""correct inverts the sensor exactly where its response keeps at least this share of a frequency."""


def first_order_lag(x: np.ndarray, lag_samples: float) -> np.ndarray:
    """x (samples along axis 0) through τ·ẏ + y = x with τ = lag_samples sample steps, exact for x linear
    between samples, from rest at x[0]."""
    values = np.asarray(x, dtype=np.float64)
    a = math.exp(-1.0 / lag_samples)
    gamma = -lag_samples * math.expm1(-1.0 / lag_samples)
    start = values[0]
    # the filter's static gain is 1, so from rest at x[0] is x[0] + the response of x − x[0] from zero
    return start + first_order_filter((1.0 - gamma, gamma - a), -a, (values - start).T).T


def window_average(x: np.ndarray, window_samples: float) -> np.ndarray:
    """y(t) = mean of x over [t − W, t] (W = window_samples sample steps, any real W > 0) along axis 0, x
    linear between samples and held at x[0] before the record."""
    values = np.asarray(x, dtype=np.float64)
    whole = math.floor(window_samples)
    after = 1.0 - (window_samples - whole)  # where t − W falls in its sample step, from its left end
    start = values[0]
    pad = np.zeros((whole + 1, *values.shape[1:]))
    z = np.concatenate([pad, values - start])  # z[j + whole + 1] = x[j] − x[0]
    integral = np.zeros_like(z)  # integral[j] = ∫ z from the padded start to sample j (trapezoids)
    np.cumsum(0.5 * (z[:-1] + z[1:]), axis=0, out=integral[1:])
    n = values.shape[0]
    # ∫ z up to t − W = integral[j] + the part-step from sample j: u·z[j] + u²/2·(z[j+1] − z[j])
    below = integral[:n] + after * z[:n] + 0.5 * after * after * (z[1 : n + 1] - z[:n])
    return start + (integral[whole + 1 :] - below) / window_samples


def sensor_response(
    omega: np.ndarray, delay_samples: float, lag_samples: float, window_samples: float
) -> np.ndarray:
    """The frequency response of delay, lag and average at ω (radians per sample, 0 … π): e^(−iωD) times
    the discrete responses of first_order_lag and window_average."""
    w = np.asarray(omega, dtype=np.float64)
    back = np.exp(-1j * w)  # z⁻¹
    response = np.exp(-1j * w * delay_samples)
    if lag_samples:
        a = math.exp(-1.0 / lag_samples)
        gamma = -lag_samples * math.expm1(-1.0 / lag_samples)
        response = response * ((1.0 - gamma) + (gamma - a) * back) / (1.0 - a * back)
    if window_samples:
        whole = math.floor(window_samples)
        part = window_samples - whole
        # trapezoid taps [½, 1, …, 1, ½] over `whole` steps: (1 + z⁻¹)/2 · Σ_{k<whole} z⁻ᵏ (Dirichlet kernel)
        half = np.sin(0.5 * w)
        dirichlet = np.divide(
            np.sin(0.5 * whole * w), half, out=np.full(w.shape, float(whole)), where=half != 0
        )
        taps = 0.5 * (1.0 + back) * np.exp(-0.5j * (whole - 1) * w) * dirichlet
        # the part-step at the window's start: weights part − part²/2 at z^−whole and part²/2 at z^−(whole+1)
        taps = taps + back**whole * ((part - 0.5 * part * part) + 0.5 * part * part * back)
        response = response * taps / window_samples
    return response


def invert_sensor(
    y: np.ndarray, delay_samples: float, lag_samples: float, window_samples: float
) -> np.ndarray:
    """x from y = (delay, lag, average)(x) along axis 0, by the rule and the end extension of the module's
    docstring."""
    values = np.asarray(y, dtype=np.float64)
    n = values.shape[0]
    if n < 2:
        return values.copy()
    shape = (n, *(1,) * (values.ndim - 1))
    steps = np.arange(n, dtype=np.float64).reshape(shape)
    slope = (values[-1] - values[0]) / (n - 1)
    rest = values - (values[0] + slope * steps)
    extended = np.concatenate([rest, -rest[-2:0:-1]])  # odd about the last sample, and so about the first
    length = extended.shape[0]
    omega = 2.0 * np.pi * np.fft.rfftfreq(length)
    response = sensor_response(omega, delay_samples, lag_samples, window_samples)
    inverse = np.conj(response) / np.maximum(np.abs(response) ** 2, MIN_INVERTED_GAIN**2)
    spectrum = np.fft.rfft(extended, axis=0) * inverse.reshape((-1, *shape[1:]))
    advance = delay_samples + lag_samples + 0.5 * window_samples  # the group delay at low frequency
    return np.fft.irfft(spectrum, length, axis=0)[:n] + (values[0] + slope * (steps + advance))


@dataclass(frozen=True)
class ChannelCorrections:
    """Per channel (name -> value; a channel not named has none of the effect): delay_s, how much the
    channel lags (s, a negative value leads); offset_m, its zero error (m); lag_s, its first-order lag's
    time constant τ ≥ 0 (s); average_s, its averaging window T ≥ 0 (s); gain_error, its scale error ε > −1
    (it reads (1 + ε)·x). Zero values leave a channel bit for bit as it is (the doctor caches on that)."""

    delay_s: dict[str, float] = field(default_factory=dict)
    offset_m: dict[str, float] = field(default_factory=dict)
    lag_s: dict[str, float] = field(default_factory=dict)
    average_s: dict[str, float] = field(default_factory=dict)
    gain_error: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for kind, values in self._tables().items():
            for name, value in values.items():
                if not math.isfinite(value):
                    raise InvalidValueError(f"sensor {kind} of channel {name} is not finite ({value})")
                if kind in ("lag_s", "average_s") and value < 0:
                    raise InvalidValueError(f"sensor {kind} of channel {name} must be >= 0 (got {value})")
                if kind == "gain_error" and value <= -1:
                    raise InvalidValueError(f"sensor gain_error of channel {name} must be > -1 (got {value})")

    def _tables(self) -> dict[str, dict[str, float]]:
        return {
            "delay_s": self.delay_s,
            "offset_m": self.offset_m,
            "lag_s": self.lag_s,
            "average_s": self.average_s,
            "gain_error": self.gain_error,
        }

    @property
    def is_identity(self) -> bool:
        """No channel has any effect: every recording is left as it is."""
        return not any(value for values in self._tables().values() for value in values.values())

    def equivalent_delay_s(self, name: str) -> float:
        """The channel's low-frequency group delay, D + τ + T/2 (s): how much a slow motion reads late."""
        return self.delay_s.get(name, 0.0) + self.lag_s.get(name, 0.0) + 0.5 * self.average_s.get(name, 0.0)

    def _dynamics(self, name: str, sample_time_s: float) -> tuple[float, float, float]:
        """Delay, lag and averaging window of the channel, in samples."""
        return (
            self.delay_s.get(name, 0.0) / sample_time_s,
            self.lag_s.get(name, 0.0) / sample_time_s,
            self.average_s.get(name, 0.0) / sample_time_s,
        )

    def correct(self, name: str, measured: np.ndarray, sample_time_s: float) -> np.ndarray:
        """The true signal from the measured one (columns of a 2-D array are signals): the offset taken
        off, divided by 1 + ε, the delay, lag and average inverted in band (module docstring)."""
        delay, lag, window = self._dynamics(name, sample_time_s)
        gain_error = self.gain_error.get(name, 0.0)
        if not (lag or window or gain_error):
            # a pure delay is undone by the spline shift, as the doctor's channel_delay always was
            x = shift_signal(measured, -delay) if delay else measured
            return x - self.offset_m.get(name, 0.0)
        x = (measured - self.offset_m.get(name, 0.0)) / (1.0 + gain_error)
        if delay or lag or window:
            x = invert_sensor(x, delay, lag, window)
        return x

    def distort(self, name: str, true: np.ndarray, sample_time_s: float) -> np.ndarray:
        """What the sensor reads from a true signal, (1 + ε)·(delay, lag, average)(x) + offset (columns of
        a 2-D array are signals)."""
        x = true
        delay, lag, window = self._dynamics(name, sample_time_s)
        if window:
            x = window_average(x, window)
        if lag:
            x = first_order_lag(x, lag)
        if delay:
            x = shift_signal(x, delay)
        gain_error = self.gain_error.get(name, 0.0)
        if gain_error:
            x = (1.0 + gain_error) * x
        return x + self.offset_m.get(name, 0.0)

    def apply(self, recording: Recording) -> Recording:
        """The recording as the true motion: every channel corrected (the recording itself when none has
        an effect)."""
        if self.is_identity:
            return recording
        dt = recording.sample_time_s
        channels = {name: self.correct(name, x, dt) for name, x in recording.channels.items()}
        return Recording(recording.time_s, channels, dict(recording.metadata))
