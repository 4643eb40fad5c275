"""A residual's autocorrelation: is it white (the Ljung-Box test), and how many independent samples is it
worth (what a likelihood ratio on it may count: the model doctor's simulation test)."""

from __future__ import annotations

import numpy as np

from estimator.distributions import chi_square_survival


def ljung_box(residual: np.ndarray, sample_time_s: float, bandwidth_Hz: float, lag_count: int = 20) -> float:
    """p of the Ljung-Box Q over `lag_count` lags of the residual decimated to twice its bandwidth."""
    step = max(1, int(1.0 / (2.0 * bandwidth_Hz * sample_time_s)))
    x = residual[::step] - np.mean(residual[::step])
    n = x.size
    denominator = float(np.dot(x, x))
    if n <= lag_count + 1 or denominator == 0.0:
        return 1.0
    lags = np.arange(1, lag_count + 1)
    rho = np.array([np.dot(x[:-k], x[k:]) / denominator for k in lags])
    return chi_square_survival(float(n * (n + 2) * np.sum(rho**2 / (n - lags))), lag_count)


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
