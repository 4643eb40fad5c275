"""estimator.laser_channels: the laser channel's delay, first-order lag, averaging, gain and offset.

distort is checked against independent references (scipy.signal.lfilter of the same first-order filter,
the analytic response to a ramp, a direct trapezoid moving average, a piecewise-linear signal refined 16
times for part-sample windows); correct against distort: a 0-20 Hz sweep at 1 kHz and 500 Hz comes back to
within 1% RMS after a 40 Hz low-pass, away from the ends, over lags 1-10 ms, averages 2-20 ms, delays
0-5 ms, gains ±5% and an offset (drawn by hypothesis, and the stiffest corner always)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import butter, lfilter, lfilter_zi, sosfiltfilt

from estimator.errors import InvalidValueError
from estimator.laser_channels import (
    MIN_INVERTED_GAIN,
    ChannelCorrections,
    first_order_lag,
    sensor_response,
    window_average,
)
from estimator.recording import Recording
from estimator.spline_shift import shift_signal

SWEEP_S = 12.0
EDGE_S = 0.5
"""The ends left out of the round trip: the last D + τ + T/2 of a record cannot be undone (the sensor has
not yet shown it), and the inverse's ringing there decays within some 0.2 s."""


def sweep(sample_rate_Hz: float) -> np.ndarray:
    """A 0-20 Hz linear sweep of ±10 mm about 2 mm, faded in smoothly over its first second (m)."""
    t = np.arange(int(SWEEP_S * sample_rate_Hz)) / sample_rate_Hz
    phase = 2.0 * np.pi * 0.5 * (20.0 / SWEEP_S) * t**2
    return 0.002 + 0.01 * np.sin(phase) * np.sin(0.5 * np.pi * np.minimum(1.0, t)) ** 2


def random_walk(seed: int, n: int = 3000) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.standard_normal(n)) * 1e-4 + 0.01


def trapezoid_average(x: np.ndarray, window: int) -> np.ndarray:
    """The mean of the piecewise-linear x over `window` whole samples, directly: taps [½, 1, …, 1, ½]/N
    on x held at x[0] before the record."""
    taps = np.ones(window + 1)
    taps[[0, -1]] = 0.5
    held = np.concatenate([np.full(window, x[0]), x])
    return np.convolve(held, taps / window, mode="valid")


@pytest.mark.parametrize("lag_samples", [0.05, 0.4, 1.0, 3.7, 25.0, 400.0])
def test_lag_equals_lfilter_of_the_same_first_order_filter(lag_samples: float) -> None:
    """The exact discretisation for an input linear between samples, as scipy.signal.lfilter runs it from
    rest at the first value (simulators/foreign/sensors.py's lag)."""
    x = random_walk(int(lag_samples * 10))
    a = math.exp(-1.0 / lag_samples)
    gamma = lag_samples * (1.0 - a)
    b, den = [1.0 - gamma, gamma - a], [1.0, -a]
    reference = lfilter(b, den, x, zi=lfilter_zi(b, den) * x[0])[0]
    assert np.max(np.abs(first_order_lag(x, lag_samples) - reference)) < 1e-12 * np.max(np.abs(x))


def test_lag_is_the_exact_response_to_a_ramp() -> None:
    """At rest, then x = x0 + β·t: y = x0 + β·(t − τ·(1 − e^(−t/τ))), at every sample (not approximately)."""
    h, tau, beta = 1e-3, 7.3e-3, 0.05
    t = np.arange(400) * h
    x = 0.01 + beta * t
    exact = 0.01 + beta * (t - tau * (1.0 - np.exp(-t / tau)))
    assert np.max(np.abs(first_order_lag(x, tau / h) - exact)) < 1e-15


@pytest.mark.parametrize("window", [1, 2, 7, 20])
def test_average_of_whole_samples_equals_the_direct_moving_average(window: int) -> None:
    """The mean over [t − N·h, t] of the signal linear between samples is the trapezoid moving average:
    also the mean of two N-sample box means a sample apart (group delay N/2, as the window's)."""
    x = random_walk(window)
    direct = trapezoid_average(x, window)
    ours = window_average(x, float(window))
    assert np.max(np.abs(ours - direct)) < 1e-12
    box = np.convolve(np.concatenate([np.full(window, x[0]), x]), np.ones(window) / window, mode="valid")
    assert np.max(np.abs(ours - 0.5 * (box[1:] + box[:-1]))) < 1e-12


@pytest.mark.parametrize("window", [0.1875, 0.5, 1.0625, 5.3125, 13.9375])
def test_average_of_part_samples_is_exact_for_a_piecewise_linear_signal(window: float) -> None:
    """A window of any length (multiples of 1/16 here) equals the whole-sample average of the same
    signal refined 16 times by linear interpolation (exact: the refined signal is the same function)."""
    x = random_walk(int(window * 16))
    fine = np.interp(np.arange((x.size - 1) * 16 + 1) / 16.0, np.arange(x.size), x)
    reference = trapezoid_average(fine, round(window * 16))[::16]
    assert np.max(np.abs(window_average(x, window) - reference)) < 1e-12


def test_distort_delays_lags_averages_then_scales_and_offsets() -> None:
    """y = (1 + ε)·(delay, lag, average)(x) + offset; an integer delay moves samples exactly; a channel
    without effects reads the truth."""
    x = random_walk(3)
    dt = 2e-3
    c = ChannelCorrections(
        {"x_s": 4 * dt}, {"x_s": 3e-4}, {"x_s": 2.5 * dt}, {"x_s": 6.5 * dt}, {"x_s": -0.04}
    )
    expected = 0.96 * shift_signal(first_order_lag(window_average(x, 6.5), 2.5), 4.0) + 3e-4
    assert np.array_equal(c.distort("x_s", x, dt), expected)
    only_delay = ChannelCorrections({"x_s": 4 * dt})
    assert np.allclose(only_delay.distort("x_s", x, dt)[4:], x[:-4], rtol=0, atol=1e-15)
    assert np.array_equal(c.distort("x_t", x, dt), x)
    assert c.equivalent_delay_s("x_s") == pytest.approx(4 * dt + 2.5 * dt + 3.25 * dt)


def test_sensor_response_is_the_response_of_distort() -> None:
    """correct divides by exactly what distort does (lag, average; the delay's spline to 2e-4 up to 40 Hz
    at 500 Hz, ω < 0.5 rad):
    the spectrum of distort's impulse response against sensor_response."""
    n, at = 4096, 100
    impulse = np.zeros(n)
    impulse[at] = 1.0
    omega = 2.0 * np.pi * np.fft.rfftfreq(n)
    for lag, window in [(3.3, 0.0), (0.0, 7.6), (9.1, 17.25), (0.2, 0.4)]:
        c = ChannelCorrections(lag_s={"a": lag * 1e-3}, average_s={"a": window * 1e-3})
        measured = np.fft.rfft(c.distort("a", impulse, 1e-3)) * np.exp(1j * omega * at)
        assert np.max(np.abs(measured - sensor_response(omega, 0.0, lag, window))) < 1e-12
    delay = ChannelCorrections({"a": 2.4e-3}).distort("a", impulse, 1e-3)
    band = omega < 2.0 * np.pi * 40.0 / 500.0  # 40 Hz at 500 Hz, the doctor's band at its slowest rate
    measured = np.fft.rfft(delay) * np.exp(1j * omega * at)
    assert np.max(np.abs(measured - sensor_response(omega, 2.4, 0.0, 0.0))[band]) < 2e-4


def round_trip_error(
    sample_rate_Hz: float, delay_s: float, lag_s: float, average_s: float, gain_error: float, offset_m: float
) -> float:
    """RMS of correct(distort(sweep)) − sweep after a 40 Hz low-pass, away from the ends, over the sweep's
    RMS about its mean."""
    dt = 1.0 / sample_rate_Hz
    x = sweep(sample_rate_Hz)
    c = ChannelCorrections(
        {"x_t": delay_s}, {"x_t": offset_m}, {"x_t": lag_s}, {"x_t": average_s}, {"x_t": gain_error}
    )
    measured = c.distort("x_t", x, dt)
    error = sosfiltfilt(butter(4, 40.0, fs=sample_rate_Hz, output="sos"), c.correct("x_t", measured, dt) - x)
    edge = int(EDGE_S * sample_rate_Hz)
    return float(np.sqrt(np.mean(error[edge:-edge] ** 2)) / np.std(x))


@given(
    sample_rate_Hz=st.sampled_from([500.0, 1000.0]),
    delay_s=st.floats(0.0, 5e-3),
    lag_s=st.one_of(st.just(0.0), st.floats(1e-3, 10e-3)),
    average_s=st.one_of(st.just(0.0), st.floats(2e-3, 20e-3)),
    gain_error=st.floats(-0.05, 0.05),
    offset_m=st.floats(-2e-3, 2e-3),
)
@settings(max_examples=40, deadline=None)
def test_correct_undoes_distort_in_band(
    sample_rate_Hz: float, delay_s: float, lag_s: float, average_s: float, gain_error: float, offset_m: float
) -> None:
    error = round_trip_error(sample_rate_Hz, delay_s, lag_s, average_s, gain_error, offset_m)
    assert error < 0.01


@pytest.mark.parametrize("sample_rate_Hz", [500.0, 1000.0])
def test_correct_undoes_the_stiffest_sensor(sample_rate_Hz: float) -> None:
    """5 ms delay, 10 ms lag and a 20 ms average keep 0.47 of 20 Hz: still above MIN_INVERTED_GAIN, so the
    band comes back exactly (bar the ends); 1.25 ms, 3.3 ms, 13.7 ms part-sample constants too."""
    kept = sensor_response(
        np.array([2 * np.pi * 20 / sample_rate_Hz]), 0, 10e-3 * sample_rate_Hz, 20e-3 * sample_rate_Hz
    )
    assert abs(kept[0]) > MIN_INVERTED_GAIN
    assert round_trip_error(sample_rate_Hz, 5e-3, 10e-3, 20e-3, 0.05, 1e-3) < 1e-3
    assert round_trip_error(sample_rate_Hz, 1.25e-3, 3.3e-3, 13.7e-3, -0.05, -1e-3) < 1e-3


def test_correct_caps_the_inverse_where_the_sensor_keeps_little() -> None:
    """At the average's zeros and far up the lag's roll-off the inverse gain never exceeds
    1/MIN_INVERTED_GAIN, so white noise comes back at most 4 times as large (in RMS)."""
    noise = np.random.default_rng(5).standard_normal(20000) * 5e-6
    c = ChannelCorrections(lag_s={"x_r": 10e-3}, average_s={"x_r": 20e-3})
    corrected = c.correct("x_r", noise, 1e-3)
    assert np.std(corrected) < np.std(noise) / MIN_INVERTED_GAIN
    omega = np.linspace(0.0, np.pi, 2001)
    response = sensor_response(omega, 0.0, 10.0, 20.0)
    inverse = np.conj(response) / np.maximum(np.abs(response) ** 2, MIN_INVERTED_GAIN**2)
    assert np.max(np.abs(inverse)) <= 1.0 / MIN_INVERTED_GAIN + 1e-12
    assert np.all(np.abs(inverse * response) <= 1.0 + 1e-12)


def test_zero_parameters_leave_the_signal_bit_for_bit() -> None:
    """The doctor caches on this: a channel whose effects are all zero, or not named, reads the truth and
    is corrected to itself exactly, 1-D and 2-D; apply returns the very recording."""
    rng = np.random.default_rng(11)
    x = rng.standard_normal(5000) * 1e-3
    columns = rng.standard_normal((5000, 3))
    zero = ChannelCorrections(
        {"x_s": 0.0}, {"x_s": 0.0}, {"x_s": 0.0}, {"x_s": 0.0}, {"x_s": 0.0, "x_t": 0.0}
    )
    assert zero.is_identity and ChannelCorrections().is_identity
    assert not ChannelCorrections(gain_error={"x_s": 0.01}).is_identity
    for c in (zero, ChannelCorrections(lag_s={"x_r": 5e-3})):
        for signal in (x, columns):
            for name in ("x_s", "x_t"):
                assert c.distort(name, signal, 1e-3).tobytes() == signal.tobytes()
                assert c.correct(name, signal, 1e-3).tobytes() == signal.tobytes()
    time_s = np.arange(5000) * 1e-3
    recording = Recording(time_s, {"x_s": x, "x_t": -x, "x_r": 2 * x})
    assert zero.apply(recording) is recording


def test_columns_of_a_2d_array_are_signals() -> None:
    """distort and correct of a 2-D array are those of each column alone."""
    rng = np.random.default_rng(2)
    columns = np.cumsum(rng.standard_normal((6000, 4)), axis=0) * 1e-5
    c = ChannelCorrections({"x_t": 1.7e-3}, {"x_t": 1e-4}, {"x_t": 4.1e-3}, {"x_t": 9.3e-3}, {"x_t": 0.02})
    for method in (c.distort, c.correct):
        together = method("x_t", columns, 2e-3)
        assert together.shape == columns.shape
        for j in range(columns.shape[1]):
            alone = method("x_t", columns[:, j], 2e-3)
            assert np.max(np.abs(together[:, j] - alone)) < 1e-15 * 1e3 * np.max(np.abs(columns))


def test_apply_corrects_every_channel() -> None:
    x = sweep(500.0)
    time_s = np.arange(x.size) / 500.0
    c = ChannelCorrections(offset_m={"x_t": 1e-3}, lag_s={"x_s": 5e-3}, gain_error={"x_r": 0.03})
    measured = {name: c.distort(name, x, 2e-3) for name in ("x_s", "x_t", "x_r")}
    corrected = c.apply(Recording(time_s, measured))
    assert np.allclose(corrected.channels["x_t"], x, rtol=0, atol=1e-15)
    assert np.allclose(corrected.channels["x_r"], x, rtol=0, atol=1e-15)
    edge = int(EDGE_S * 500)
    assert np.max(np.abs(corrected.channels["x_s"] - x)[edge:-edge]) < 1e-7


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"lag_s": {"x_s": -1e-3}}, "lag_s of channel x_s must be >= 0"),
        ({"average_s": {"x_t": -0.02}}, "average_s of channel x_t must be >= 0"),
        ({"gain_error": {"x_r": -1.0}}, "gain_error of channel x_r must be > -1"),
        ({"delay_s": {"x_r": math.nan}}, "delay_s of channel x_r is not finite"),
    ],
)
def test_bad_values_are_one_line_errors(kwargs: dict, message: str) -> None:
    with pytest.raises(InvalidValueError, match=message):
        ChannelCorrections(**kwargs)
