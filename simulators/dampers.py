"""Damper characteristics for simulated vehicles: an embedded valve-model damper (not of the tanh form), the
paper's identified tanh dampers, and real measured tables read from ../shared/realdata."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from estimator.damper import PiecewiseLinearCurve, TanhCurve

SHARED_REALDATA = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"
"""Where the project's shared real damper data lives (beside the project, never copied into it)."""


def valve_damper(
    bleed_Ns_per_m: float = 4500.0,
    blowoff_extension_N: float = 420.0,
    blowoff_compression_N: float = 260.0,
    high_speed_extension_Ns_per_m: float = 1900.0,
    high_speed_compression_Ns_per_m: float = 900.0,
) -> PiecewiseLinearCurve:
    """A passenger-car damper built from its valve physics: a bleed orifice with a quadratic-to-linear law
    below the blow-off force, then the blow-off valve's linear slope; stiffer in extension.

    Tabulated on a fine grid (a table, as a dyno would give); deliberately not of the tanh form of eq (10).
    """
    velocity = np.linspace(-1.5, 1.5, 301)
    force = np.empty_like(velocity)
    for side, sign, blowoff, slope in (
        ("ext", 1.0, blowoff_extension_N, high_speed_extension_Ns_per_m),
        ("comp", -1.0, blowoff_compression_N, high_speed_compression_Ns_per_m),
    ):
        mask = velocity >= 0 if side == "ext" else velocity < 0
        speed = np.abs(velocity[mask])
        knee = blowoff / bleed_Ns_per_m
        bleed = bleed_Ns_per_m * speed * (1.0 + 0.35 * speed / knee) / 1.35  # orifice: progressive
        open_ = blowoff + slope * (speed - knee)
        force[mask] = sign * np.where(speed < knee, np.minimum(bleed, blowoff), open_)
    return PiecewiseLinearCurve(velocity, force)


PAPER_TANH_MAXWELL = TanhCurve(c_s=68.647, kappa=937.67, mu=1.336, beta=-1.203)
"""The paper's Table 3 tanh fit of the motorcycle fork identified with the Maxwell tyre model."""


def load_table(path: Path | str, scale: float = 1.0) -> PiecewiseLinearCurve:
    """A velocity_m_s,force_N table (e.g. damper_table_suv_rear.csv). Positive velocity is extension."""
    with Path(path).open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    velocity = np.array([float(r["velocity_m_s"]) for r in rows])
    force = np.array([float(r["force_N"]) for r in rows]) * scale
    return PiecewiseLinearCurve(velocity, force)


def suv_rear_table(scale: float = 1.0) -> PiecewiseLinearCurve:
    """The 13-point passenger-car rear damper table of ../shared/realdata (positive velocity = extension)."""
    return load_table(SHARED_REALDATA / "damper_table_suv_rear.csv", scale)


def smooth_table(curve: PiecewiseLinearCurve, step_m_s: float = 0.002) -> PiecewiseLinearCurve:
    """The table as a real damper behaves: a monotone cubic (PCHIP) through its points, C1-smooth, linear
    beyond the ends with the end slopes; tabulated densely (step_m_s) so it is evaluated by np.interp."""
    from scipy.interpolate import PchipInterpolator

    lo, hi = float(curve.velocity_m_s[0]), float(curve.velocity_m_s[-1])
    span = max(hi - lo, 1.0)
    grid = np.arange(lo - span, hi + span + step_m_s / 2, step_m_s)
    interp = PchipInterpolator(curve.velocity_m_s, curve.force_N, extrapolate=False)
    slope = interp.derivative()
    inside = interp(np.clip(grid, lo, hi))
    force = inside + np.where(grid < lo, float(slope(lo)) * (grid - lo), 0.0)
    force = force + np.where(grid > hi, float(slope(hi)) * (grid - hi), 0.0)
    return PiecewiseLinearCurve(grid, force)
