"""The report's plots, drawn into axes the caller places: the damper curve with its 95% band (left and right
overlaid on an axle), the sweep over time (plate, wheel and body per side) and the transmissibility over
frequency (wheel over plate and body over plate). The PDF draws them on its pages, the HTML page as SVG
images; both call `draw`.

Only matplotlib's object API (Figure, Axes), never pyplot's global state: the service renders reports in
worker threads.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from scipy.signal import csd, welch

from estimator.damper import TanhCurve
from estimator.recording import Recording
from service.api.results import CurveOut
from service.plots import COLOURS
from service.report.content import Plot, ReportContent

SIDES = {"": "", "_l": "left", "_r": "right"}
"""Channel suffix -> side (quarter car: none)."""
TRACES = (("x_r", "plate", "0.35"), ("x_t", "wheel", "tab:orange"), ("x_s", "body", "tab:blue"))
"""Channel, name and colour of each trace over time."""
MAX_POINTS = 3000
"""Points per trace over time: a 20 s sweep at 1 kHz is shown by its envelope, not 20 000 vertices."""
SEGMENT_S = 2.0
"""Welch segment of the transmissibility: 0.5 Hz resolution."""
MIN_FREQUENCY_HZ = 0.5
"""Below it a sweep holds too few periods for a ratio of amplitudes."""
STYLE = {
    "pdf.fonttype": 42,  # TrueType: the PDF's text is searchable and copies as typed
    "svg.hashsalt": "shockbench report",  # the SVG's element ids the same on every run
    "svg.fonttype": "path",  # the SVG needs no font on the reader's machine
}
_RENDERING = threading.Lock()


@contextmanager
def rendering() -> Iterator[None]:
    """matplotlib's settings for a report, one report at a time: rcParams are global to the process and
    the service renders in worker threads."""
    with _RENDERING, matplotlib.rc_context(STYLE):
        yield


def draw_curves(ax: Axes, curves: Sequence[CurveOut]) -> None:
    """Identified points, their 95% band and the tanh fit of each corner, on one axes."""
    for c in curves:
        colour = COLOURS.get(c.corner, "tab:green")
        label = "damper" if c.corner == "single" else f"{c.corner}"
        v, f = np.asarray(c.velocity_m_s), np.asarray(c.force_N)
        if c.force_N_low is not None and c.force_N_high is not None:
            ax.fill_between(
                v, c.force_N_low, c.force_N_high, color=colour, alpha=0.2, lw=0, label=f"{label}: 95% band"
            )
        ax.plot(v, f, "o", color=colour, ms=3.5, label=f"{label}: identified")
        dense = np.linspace(v[0], v[-1], 200)
        fit = TanhCurve(**c.tanh.model_dump(include={"c_s", "kappa", "mu", "beta"})).force(dense)
        ax.plot(dense, fit, "-", color=colour, lw=1.2, label=f"{label}: tanh fit")
    ax.axhline(0, color="0.8", lw=0.6)
    ax.axvline(0, color="0.8", lw=0.6)
    ax.set_xlabel("suspension velocity (m/s), extension positive", fontsize=8)
    ax.set_ylabel("damper force (N)", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="upper left", ncols=2 if len(curves) > 1 else 1)


def sides(recording: Recording) -> list[str]:
    """The channel suffixes the recording has a plate, wheel and body for."""
    return [s for s in SIDES if all(f"{name}{s}" in recording.channels for name, _, _ in TRACES)]


def envelope(
    time_s: np.ndarray, values: np.ndarray, points: int = MAX_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    """At most `points` points showing every excursion: the minimum and maximum of each of points/2
    buckets, in time order."""
    if values.size <= points:
        return time_s, values
    buckets = points // 2
    size = values.size // buckets
    shaped = values[: buckets * size].reshape(buckets, size)
    low, high = np.argmin(shaped, axis=1), np.argmax(shaped, axis=1)
    offsets = np.arange(buckets) * size
    chosen = np.sort(np.concatenate([offsets + low, offsets + high]))
    return time_s[chosen], values[chosen]


def draw_sweep(axes: Sequence[Axes], recording: Recording) -> None:
    """Plate, wheel and body displacement over time, one axes per side."""
    for ax, suffix in zip(axes, sides(recording), strict=False):
        for channel, name, colour in TRACES:
            t, x = envelope(recording.time_s, recording.channels[f"{channel}{suffix}"] * 1e3)
            ax.plot(t, x, color=colour, lw=0.6, label=name)
        ax.set_ylabel(f"{SIDES[suffix]} (mm)".strip() if suffix else "displacement (mm)", fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7, loc="upper right", ncols=3)
    axes[-1].set_xlabel("time (s)", fontsize=8)


def transmissibility(
    recording: Recording, suffix: str, band_Hz: tuple[float, float] | None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Frequencies (Hz) and |H1| = |S_plate,out / S_plate,plate| of the wheel and the body, where the plate
    moved: inside the sweep's band when known, else where its power is above 1% of its peak (from
    MIN_FREQUENCY_HZ up in both cases)."""
    fs = 1.0 / recording.sample_time_s
    segment = min(recording.time_s.size, round(SEGMENT_S * fs))
    plate = recording.channels[f"x_r{suffix}"]
    frequency, power = welch(plate - plate.mean(), fs, nperseg=segment)
    low, high = sorted(band_Hz) if band_Hz is not None else (0.0, np.inf)
    inside = (frequency >= max(low, MIN_FREQUENCY_HZ)) & (frequency <= high) & (power > 0)
    moved = inside if band_Hz is not None else inside & (power > 0.01 * power.max())
    ratios = {}
    for channel, name, _ in TRACES[1:]:
        out = recording.channels[f"{channel}{suffix}"]
        _, cross = csd(plate - plate.mean(), out - out.mean(), fs, nperseg=segment)
        ratios[name] = np.abs(cross[moved]) / power[moved]
    return frequency[moved], ratios


def draw_transmissibility(ax: Axes, recording: Recording, band_Hz: tuple[float, float] | None) -> None:
    """Wheel and body over plate by frequency; on an axle, left solid and right dashed."""
    for suffix in sides(recording):
        frequency, ratios = transmissibility(recording, suffix, band_Hz)
        style = "--" if suffix == "_r" else "-"
        for (_, name, colour), ratio in zip(TRACES[1:], ratios.values(), strict=True):
            label = f"{SIDES[suffix]} {name}".strip()
            ax.plot(frequency, ratio, style, color=colour, lw=1.0, label=f"{label} / plate")
    ax.axhline(1.0, color="0.6", lw=0.6)
    ax.set_xlabel("frequency (Hz)", fontsize=8)
    ax.set_ylabel("amplitude ratio", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="upper right")


def draw(plot: Plot, content: ReportContent, fig: Figure, rect: tuple[float, float, float, float]) -> None:
    """Draw `plot` into `rect` (left, bottom, width, height as fractions of `fig`), its panels stacked."""
    left, bottom, width, height = rect
    if plot.kind == "curves":
        draw_curves(fig.add_axes(rect), content.curves)
        return
    assert content.recording is not None
    if plot.kind == "transmissibility":
        draw_transmissibility(fig.add_axes(rect), content.recording, content.sweep_band_Hz)
        return
    gap = 0.08 * height / plot.panels
    each = (height - gap * (plot.panels - 1)) / plot.panels
    axes: list[Axes] = []
    for k in range(plot.panels):
        y = bottom + height - (k + 1) * each - k * gap
        axes.append(fig.add_axes((left, y, width, each), sharex=axes[0] if axes else None))
    for ax in axes[:-1]:
        ax.tick_params(labelbottom=False)
    draw_sweep(axes, content.recording)


def plot_figure(plot: Plot, content: ReportContent, width_in: float) -> Figure:
    """`plot` alone on a figure `width_in` wide (the HTML page's images)."""
    fig = Figure(figsize=(width_in, plot.height_in))
    margin_x, margin_y = 0.75 / width_in, 0.45 / plot.height_in
    draw(
        plot,
        content,
        fig,
        (margin_x, margin_y, 1 - margin_x - 0.2 / width_in, 1 - margin_y - 0.1 / plot.height_in),
    )
    return fig
