"""RMS of named series per bin of a variable: per band of a sweep's instantaneous frequency, or per
quantile bin of a variable (a suspension velocity, a deflection). The model doctor locates a disagreement
with them (estimator.doctor.residuals)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BAND_WIDTH_HZ = 2.0
BINS = 8


@dataclass(frozen=True)
class Profile:
    """RMS of named series per bin of a variable (edges in its unit; NaN: too few samples in the bin)."""

    variable: str
    unit: str
    edges: np.ndarray
    values: dict[str, np.ndarray]

    def worst(self, name: str) -> tuple[float, float]:
        """The edges of the bin where the series `name` is largest (NaN: none has samples enough)."""
        values = self.values[name]
        if not np.any(np.isfinite(values)):
            return float("nan"), float("nan")
        k = int(np.nanargmax(values))
        return float(self.edges[k]), float(self.edges[k + 1])


def _profile(
    variable: str, unit: str, edges: np.ndarray, which: np.ndarray, series: dict[str, np.ndarray], least: int
) -> Profile:
    """which: each sample's bin (none outside 0 … edges.size − 2); a bin needs `least` samples."""
    bins = range(edges.size - 1)
    values = {
        name: np.array(
            [np.sqrt(np.mean(x[which == k] ** 2)) if np.sum(which == k) >= least else np.nan for k in bins]
        )
        for name, x in series.items()
    }
    return Profile(variable, unit, edges, values)


def band_rms(series: dict[str, np.ndarray], frequency_Hz: np.ndarray, top_Hz: float) -> Profile:
    """Per band of the sweep (at least 10 samples)."""
    edges = np.arange(0.0, top_Hz + BAND_WIDTH_HZ, BAND_WIDTH_HZ)
    which = np.searchsorted(edges, frequency_Hz, side="right") - 1
    return _profile("sweep frequency", "Hz", edges, which, series, 10)


def binned_rms(variable: np.ndarray, series: dict[str, np.ndarray], name: str, unit: str) -> Profile:
    """Per BINS quantile bins of the variable."""
    edges = np.unique(np.quantile(variable, np.linspace(0.0, 1.0, BINS + 1)))
    which = np.clip(np.searchsorted(edges, variable, side="right") - 1, 0, edges.size - 2)
    return _profile(name, unit, edges, which, series, 1)
