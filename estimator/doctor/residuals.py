"""Locate a disagreement: which channel, which part of the sweep, which range of suspension velocity,
deflection and tyre deflection, and whether what is left looks like noise.

Two residuals are analysed:

- the *output error* (m): the model simulated from the measured plate, minus the measured readings, per
  channel (estimator.doctor.simulation);
- the *equation error* (N): the equations of motion evaluated with the fitted unknowns, per equation
  (body/wheel, or left wheel/right wheel/heave/roll), at the samples the fit used.

The sweep's instantaneous frequency at every sample is read from the plate channel itself (peak of a
short-time spectrum), so a time in the recording maps to a frequency band of the sweep.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.digital_filters import welch_density
from estimator.doctor.model import FittedModel
from estimator.doctor.simulation import diverged

BAND_WIDTH_HZ = 2.0
WINDOW_S = 0.5
"""Short-time spectrum window for the sweep frequency."""
REST_FRACTION = 0.1
"""Where the plate's amplitude is below this fraction of its largest, the plate rests (no sweep frequency)."""
BINS = 8
TIME_WINDOW_S = 0.5
WHITENESS_LAGS = 20
WHITENESS_LEVEL = 0.01


def short_time_magnitude(
    x: np.ndarray, sample_rate_Hz: float, segment: int, fft_size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies, segment centre times and |STFT| (frequencies, segments) as scipy.signal.stft(x, fs,
    nperseg=segment, noverlap=3·segment//4, nfft=fft_size) has them, up to its constant scale 1/Σwindow:
    periodic Hann window, segment//2 zeros at either end, zeros after to fill the last segment. Here in
    numpy so that a diagnosis does not import scipy.signal (1-2 s a process)."""
    step = segment - 3 * segment // 4
    half = segment // 2
    padded = np.concatenate([np.zeros(half), np.asarray(x, dtype=float), np.zeros(half)])
    padded = np.concatenate([padded, np.zeros((-(padded.size - segment) % step) % segment)])
    starts = np.arange(0, padded.size - segment + 1, step)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(segment) / segment)
    spectrum = np.fft.rfft(window * padded[starts[:, None] + np.arange(segment)], n=fft_size, axis=1)
    times = starts / sample_rate_Hz  # the segment centres, less the leading zeros
    return np.fft.rfftfreq(fft_size, 1.0 / sample_rate_Hz), times, np.abs(spectrum).T


def sweep_frequency_Hz(plate_m: np.ndarray, sample_time_s: float) -> np.ndarray:
    """The sweep's instantaneous frequency at every sample (NaN where the plate rests)."""
    rate = 1.0 / sample_time_s
    window = max(16, round(WINDOW_S * rate))
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


@dataclass(frozen=True)
class BandProfile:
    """RMS of named series per frequency band of the sweep (NaN: no samples in the band)."""

    edges_Hz: np.ndarray
    values: dict[str, np.ndarray]

    def labels(self) -> list[str]:
        return [f"{lo:g}-{hi:g} Hz" for lo, hi in zip(self.edges_Hz[:-1], self.edges_Hz[1:], strict=True)]


@dataclass(frozen=True)
class BinProfile:
    """RMS of named series in quantile bins of a variable (edges in the variable's unit)."""

    variable: str
    unit: str
    edges: np.ndarray
    values: dict[str, np.ndarray]


@dataclass(frozen=True)
class Whiteness:
    """Ljung-Box test of a residual decimated to its bandwidth: white when the p-value is above
    WHITENESS_LEVEL."""

    statistic: float
    lags: int
    p_value: float

    @property
    def white(self) -> bool:
        return self.p_value > WHITENESS_LEVEL


def band_rms(series: dict[str, np.ndarray], frequency_Hz: np.ndarray, top_Hz: float) -> BandProfile:
    edges = np.arange(0.0, top_Hz + BAND_WIDTH_HZ, BAND_WIDTH_HZ)
    values = {}
    for name, x in series.items():
        rms = np.full(edges.size - 1, np.nan)
        for k in range(edges.size - 1):
            inside = (frequency_Hz >= edges[k]) & (frequency_Hz < edges[k + 1])
            if np.count_nonzero(inside) >= 10:
                rms[k] = float(np.sqrt(np.mean(x[inside] ** 2)))
        values[name] = rms
    return BandProfile(edges, values)


def binned_rms(variable: np.ndarray, series: dict[str, np.ndarray], name: str, unit: str) -> BinProfile:
    edges = np.unique(np.quantile(variable, np.linspace(0.0, 1.0, BINS + 1)))
    which = np.clip(np.searchsorted(edges, variable, side="right") - 1, 0, edges.size - 2)
    values = {
        key: np.array(
            [
                np.sqrt(np.mean(x[which == k] ** 2)) if np.any(which == k) else np.nan
                for k in range(edges.size - 1)
            ]
        )
        for key, x in series.items()
    }
    return BinProfile(name, unit, edges, values)


def ljung_box(residual: np.ndarray, sample_time_s: float, bandwidth_Hz: float) -> Whiteness:
    """Ljung-Box Q over WHITENESS_LAGS lags of the residual decimated to twice its bandwidth."""
    step = max(1, int(1.0 / (2.0 * bandwidth_Hz * sample_time_s)))
    x = residual[::step] - np.mean(residual[::step])
    n = x.size
    denominator = float(np.dot(x, x))
    if n <= WHITENESS_LAGS + 1 or denominator == 0.0:
        return Whiteness(0.0, WHITENESS_LAGS, 1.0)
    lags = np.arange(1, WHITENESS_LAGS + 1)
    rho = np.array([np.dot(x[:-k], x[k:]) / denominator for k in lags])
    q = float(n * (n + 2) * np.sum(rho**2 / (n - lags)))
    return Whiteness(q, WHITENESS_LAGS, chi_square_survival(q, WHITENESS_LAGS))  # the χ² law's upper tail


def chi_square_survival(statistic: float, degrees: int) -> float:
    """P(χ² > statistic) with `degrees` degrees of freedom (log_chi_square_survival)."""
    return min(1.0, math.exp(log_chi_square_survival(statistic, degrees)))


def log_chi_square_survival(statistic: float, degrees: int) -> float:
    """ln P(χ² > statistic) with `degrees` degrees of freedom (scipy.special.chdtrc's tail, in logarithms so
    that two very significant statistics still compare: their p-values would both underflow to 0). Even
    degrees: the Poisson sum e^(−s/2)·Σ_{k<degrees/2} (s/2)^k / k!; odd: erfc(√(s/2)) plus
    e^(−s/2)·Σ_{k=1}^{(degrees−1)/2} (s/2)^(k−1/2) / Γ(k + 1/2), erfc(x) by its asymptotic
    e^(−x²)/(x√π) beyond x = 25 (relative error below 0.1%). Why not scipy: importing scipy.special
    costs a diagnosis some 0.1 s for this one tail."""
    if degrees <= 0:
        raise ValueError(f"chi_square_survival takes a positive number of degrees, not {degrees}")
    if statistic <= 0:
        return 0.0
    if not math.isfinite(statistic):
        return -math.inf
    half = statistic / 2.0
    if half == 0.0:  # a statistic so small that half of it underflows: P = 1
        return 0.0
    log_half = math.log(half)
    if degrees % 2 == 0:
        terms = [k * log_half - half - math.lgamma(k + 1) for k in range(degrees // 2)]
    else:
        root = math.sqrt(half)
        tail = math.log(math.erfc(root)) if root < 25.0 else -half - math.log(root * math.sqrt(math.pi))
        terms = [tail] + [
            (k - 0.5) * log_half - half - math.lgamma(k + 0.5) for k in range(1, (degrees + 1) // 2)
        ]
    top = max(terms)
    return min(0.0, top + math.log(sum(math.exp(t - top) for t in terms)))


def effective_samples(residual: np.ndarray) -> float:
    """n / (1 + 2·Σρ_k): how many independent samples a correlated residual is worth (the sum runs to the
    first negative autocorrelation)."""
    x = residual - np.mean(residual)
    n = x.size
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(np.abs(spectrum) ** 2)[:n]
    if acf[0] <= 0:
        return float(n)
    rho = acf / acf[0]
    negative = np.nonzero(rho[1:] < 0)[0]
    stop = negative[0] + 1 if negative.size else n
    return float(n / max(1.0, 1.0 + 2.0 * np.sum(rho[1:stop])))


@dataclass
class Localisation:
    """Where a fitted model disagrees with the measurement."""

    gap_m: float
    channel_rms_m: dict[str, float]
    equation_rms_N: dict[str, float]
    output_bands: BandProfile
    equation_bands: BandProfile
    by_variable: list[BinProfile]
    whiteness: dict[str, Whiteness]
    spectra: dict[str, tuple[np.ndarray, np.ndarray]]
    """Channel -> (frequency Hz, one-sided power density m²/Hz) of the output-error residual."""
    worst_time_s: tuple[float, float]
    """The window of TIME_WINDOW_S where the output error (all channels) is largest."""

    def worst_channel(self) -> str:
        return max(self.channel_rms_m, key=lambda c: self.channel_rms_m[c])

    def worst_band(self, profile: BandProfile, name: str) -> tuple[float, float]:
        values = profile.values[name]
        if not np.any(np.isfinite(values)):
            return float("nan"), float("nan")
        k = int(np.nanargmax(values))
        return float(profile.edges_Hz[k]), float(profile.edges_Hz[k + 1])

    def describe(self) -> str:
        """One sentence: which channel, which time and band of the sweep, which equation and range of
        suspension velocity, white or not."""
        if not np.isfinite(self.gap_m):
            return "the model diverges when driven by the measured plate"
        channel = self.worst_channel()
        lo, hi = self.worst_band(self.output_bands, channel)
        equation = max(self.equation_rms_N, key=lambda e: self.equation_rms_N[e])
        elo, ehi = self.worst_band(self.equation_bands, equation)
        velocity = self.by_variable[0]
        k = int(np.nanargmax(velocity.values[equation]))
        white = [c for c, w in self.whiteness.items() if w.white]
        start, stop = self.worst_time_s
        return (
            f"gap {self.gap_m * 1e6:.1f} µm; largest on {channel} "
            f"({self.channel_rms_m[channel] * 1e6:.1f} µm RMS), at {start:.1f}-{stop:.1f} s, "
            f"in the {lo:g}-{hi:g} Hz part of the sweep; largest equation residual: {equation} "
            f"({self.equation_rms_N[equation]:.1f} N RMS, {elo:g}-{ehi:g} Hz, most at suspension velocities "
            f"{velocity.edges[k]:+.3f}..{velocity.edges[k + 1]:+.3f} m/s); output error "
            + ("white on " + ", ".join(white) if white else "not white on any channel")
        )


def locate(model: FittedModel, output_residual: dict[str, np.ndarray], gap_m: float) -> Localisation:
    """Residual analysis of one fitted model; output_residual: its output error per channel (m). A model
    whose simulation diverged has residuals near the float range's end: their squares overflow to inf,
    which is what the localisation should say of it, without numpy's overflow warnings on a user's
    terminal."""
    with np.errstate(over="ignore", invalid="ignore"):
        return _locate(model, output_residual, gap_m)


def _locate(model: FittedModel, output_residual: dict[str, np.ndarray], gap_m: float) -> Localisation:
    signals = model.signals
    dt = signals.sample_time_s
    index = model.system.sample_index
    filters = model.system.filters
    plate = model.signals.recording.channels["x_r_l" if model.vehicle.is_axle else "x_r"]
    frequency = sweep_frequency_Hz(plate, dt)
    measured = model.signals.recording.channels
    finite = {c: r for c, r in output_residual.items() if not diverged(r, measured[c])}
    equation_residual = model.residuals()
    equations = dict(zip(signals.equations, equation_residual, strict=True))
    by_variable = []  # of the first corner (the left one of an axle)
    for label, unit, pick in (
        ("suspension velocity", "m/s", lambda c: c.velocity_m_s),
        ("suspension deflection", "m", lambda c: c.deflection_m),
        ("tyre deflection", "m", lambda c: c.tyre_deflection_smooth_m),
    ):
        corner = signals.corners[0]
        by_variable.append(binned_rms(pick(corner)[index], equations, label, unit))
    worst_time = (float("nan"), float("nan"))
    if finite:
        power = np.mean([r**2 for r in finite.values()], axis=0)
        window = max(1, round(TIME_WINDOW_S / dt))
        running = np.convolve(power, np.ones(window) / window, mode="valid")
        start = int(np.argmax(running)) * dt
        worst_time = (start, start + window * dt)
    spectra = {}
    for channel, r in finite.items():
        f, p = welch_density(r - np.mean(r), 1.0 / dt, min(r.size, 2048))
        spectra[channel] = (f, p)
    return Localisation(
        gap_m=gap_m,
        channel_rms_m={c: float(np.sqrt(np.mean(r**2))) for c, r in output_residual.items()},
        equation_rms_N={e: float(np.sqrt(np.mean(r**2))) for e, r in equations.items()},
        output_bands=band_rms(finite, frequency, filters.excitation_top_Hz),
        equation_bands=band_rms(equations, frequency[index], filters.excitation_top_Hz),
        by_variable=by_variable,
        whiteness={c: ljung_box(r, dt, filters.equation_cutoff_Hz) for c, r in finite.items()},
        spectra=spectra,
        worst_time_s=worst_time,
    )
