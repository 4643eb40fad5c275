"""Plots of identified damper curves (PNG or SVG by the file suffix), for the CLI and the service."""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display on a bench PC service or in CI
import matplotlib.pyplot as plt
import numpy as np

from estimator.damper import TanhCurve
from estimator.dynamics import ForceCurve
from estimator.identify import IdentificationResult

COLOURS = {"single": "tab:blue", "left": "tab:blue", "right": "tab:red"}


def curve_figure(result: IdentificationResult, truth: dict[str, ForceCurve] | None = None) -> plt.Figure:
    """Identified points with their 95% confidence band, their tanh fit, and (for simulated data) the true
    curve, per corner."""
    fig, ax = plt.subplots(figsize=(7.5, 5.0), dpi=110)
    for index, c in enumerate(result.curves):
        colour = COLOURS.get(c.corner, "tab:green")
        label = "damper" if c.corner == "single" else f"{c.corner} damper"
        v = c.curve.velocity_m_s
        dense = np.linspace(v[0], v[-1], 300)
        band = result.curve_band(index)
        if band is not None:
            ax.fill_between(v, band[0], band[1], color=colour, alpha=0.2, lw=0, label=f"{label}: 95% band")
        ax.plot(v, c.curve.force_N, "o", color=colour, label=f"{label}: identified points")
        ax.plot(
            dense,
            TanhCurve(**c.tanh.curve.as_dict()).force(dense),
            "-",
            color=colour,
            label=f"{label}: tanh fit (eq 10)",
        )
        if c.tanh.outliers:
            ax.plot(
                v[c.tanh.outliers],
                c.curve.force_N[c.tanh.outliers],
                "x",
                color="k",
                ms=10,
                label="outlier (left out of the fit)",
            )
        if truth and c.corner in truth:
            ax.plot(dense, truth[c.corner].force(dense), "--", color="0.4", label=f"{label}: true curve")
    ax.axhline(0, color="0.8", lw=0.8)
    ax.axvline(0, color="0.8", lw=0.8)
    ax.set_xlabel("suspension velocity ẋ_s − ẋ_t (m/s), extension positive")
    ax.set_ylabel("damper force (N)")
    m = result.model
    ax.set_title(f"Identified damper curve ({m.tyre_model.value} tyre, {result.solver.value} solver)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    return fig


def save_curve_plot(
    result: IdentificationResult, path: Path | str, truth: dict[str, ForceCurve] | None = None
) -> Path:
    path = Path(path)
    fig = curve_figure(result, truth)
    try:
        fig.savefig(path, format=path.suffix.lstrip(".").lower() or "png")
    finally:
        plt.close(fig)
    return path


def curve_plot_bytes(result: IdentificationResult, formats: tuple[str, ...] = ("png",)) -> dict[str, bytes]:
    """The curve plot in each of formats (format -> file bytes), drawn from one figure: laying it out
    costs about a third of a PNG's time, so the service's job pays it once for its PNG and SVG."""
    fig = curve_figure(result)
    files = {}
    try:
        for fmt in formats:
            buffer = io.BytesIO()
            fig.savefig(buffer, format=fmt)
            files[fmt] = buffer.getvalue()
    finally:
        plt.close(fig)
    return files
