"""Dampers of the independent world: force-velocity tables made smooth by a monotone cubic (PCHIP), as a real
damper is smooth, extended linearly with the end slopes beyond the table.

Tables come from ../shared/realdata (read there, never copied): the 13-point SUV rear table, and the two
crank-dynamometer logs of an FSAE damper reduced to a table here (displacement low-passed at 15 Hz by a
forward-backward 2nd-order Butterworth as its authors do, differentiated, force binned by velocity, the gas
force removed, made dissipative and monotone). A third kind is a valve model written from the flow through a
damper piston: laminar leakage, a bleed orifice (flow ∝ √Δp) and a blow-off valve that opens above its
cracking force (area ∝ the excess force), tabulated densely.

Positive velocity is extension (the suspension lengthens); the damper force then acts to shorten it.
"""

from __future__ import annotations

import bisect
import csv
import itertools
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.optimize import isotonic_regression
from scipy.signal import butter, filtfilt

REALDATA = Path(__file__).resolve().parents[2].parent / "shared" / "realdata"
SUV_TABLE = "damper_table_suv_rear.csv"
DYNO_LOGS = ("damper_dyno_s5_100psi.csv", "damper_dyno_s6_100psi_b.csv")


class _SmoothMonotone:
    """A PCHIP through (x, y), linear with the end slopes outside, evaluated on Python floats (the ODE's
    right-hand side calls it once per stage; numpy per call would dominate the run time). y must increase,
    so the law has an exact inverse (`inverse`), found per piece by safeguarded Newton steps."""

    def __init__(self, x: np.ndarray, y: np.ndarray) -> None:
        self.interpolator = PchipInterpolator(x, y, extrapolate=False)
        self.breaks = [float(b) for b in self.interpolator.x]
        self.values = [float(v) for v in y]
        self.coefficients = [tuple(float(c) for c in column) for column in self.interpolator.c.T]
        slope = self.interpolator.derivative()
        self.low = (self.breaks[0], self.values[0], float(slope(x[0])))
        self.high = (self.breaks[-1], self.values[-1], float(slope(x[-1])))

    def __call__(self, x: float) -> float:
        if x <= self.low[0]:
            return self.low[1] + self.low[2] * (x - self.low[0])
        if x >= self.high[0]:
            return self.high[1] + self.high[2] * (x - self.high[0])
        index = bisect.bisect_right(self.breaks, x) - 1
        a, b, c, d = self.coefficients[index]
        u = x - self.breaks[index]
        return ((a * u + b) * u + c) * u + d

    def inverse(self, y: float) -> float:
        """The x at which the law takes the value y."""
        if y <= self.low[1]:
            return self.low[0] + (y - self.low[1]) / self.low[2]
        if y >= self.high[1]:
            return self.high[0] + (y - self.high[1]) / self.high[2]
        index = bisect.bisect_right(self.values, y) - 1
        a, b, c, d = self.coefficients[index]
        lo, hi = 0.0, self.breaks[index + 1] - self.breaks[index]
        target = y - d
        u = hi * target / (self.values[index + 1] - d)  # the chord's answer
        for _ in range(60):
            residual = ((a * u + b) * u + c) * u - target
            if residual > 0.0:
                hi = u
            else:
                lo = u
            if abs(residual) <= 1e-13 * (abs(y) + 1.0):
                break
            slope = (3.0 * a * u + 2.0 * b) * u + c
            step = u - residual / slope if slope > 0.0 else 0.5 * (lo + hi)
            u = step if lo < step < hi else 0.5 * (lo + hi)
        return self.breaks[index] + u


@dataclass(frozen=True)
class TableDamper:
    """A damper given by a strictly increasing force-velocity table through (0, 0)."""

    name: str
    velocity_m_s: np.ndarray
    force_N: np.ndarray
    _law: _SmoothMonotone = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        v, f = np.asarray(self.velocity_m_s, float), np.asarray(self.force_N, float)
        if v.shape != f.shape or v.size < 3:
            raise ValueError(f"damper {self.name}: a table needs three or more (velocity, force) pairs")
        if np.any(np.diff(v) <= 0) or np.any(np.diff(f) <= 0):
            raise ValueError(f"damper {self.name}: velocity and force must both increase along the table")
        object.__setattr__(self, "_law", _SmoothMonotone(v, f))

    def force(self, velocity_m_s: float) -> float:
        """Damper force (N) at the suspension velocity (m/s, extension positive)."""
        return self._law(velocity_m_s)

    def velocity(self, force_N: float) -> float:
        """The velocity at which the damper carries force_N: the inverse of force() (used when the damper
        sits in series with a compliant mount)."""
        return self._law.inverse(force_N)

    def scaled(self, force_scale: float, velocity_scale: float = 1.0) -> TableDamper:
        """The same damper valved harder or softer (force × force_scale, at velocity × velocity_scale)."""
        return TableDamper(
            f"{self.name} ×{force_scale:.2f}",
            self.velocity_m_s * velocity_scale,
            self.force_N * force_scale,
        )

    @property
    def interpolant(self) -> PchipInterpolator:
        return self._law.interpolator


def suv_table(folder: Path = REALDATA) -> TableDamper:
    """The passenger-car rear damper table (positive velocity read as extension)."""
    with (folder / SUV_TABLE).open(newline="") as handle:
        rows = [(float(r["velocity_m_s"]), float(r["force_N"])) for r in csv.DictReader(handle)]
    table = np.array(sorted(rows))
    return TableDamper("SUV rear table", table[:, 0], table[:, 1])


def dyno_table(log: str, folder: Path = REALDATA, bins: int = 8) -> TableDamper:
    """A force-velocity table from a crank-dyno log: `bins` velocity bins per direction (median force)."""
    times, force, displacement = [], [], []
    with (folder / log).open(newline="") as handle:
        for row in csv.DictReader(handle):
            times.append(datetime.fromisoformat(row["Timestamp"]).timestamp())
            force.append(float(row["Force (N)"]))
            displacement.append(float(row["Displacement (mm)"]) * 1e-3)
    t, f, x = np.array(times), np.array(force), np.array(displacement)
    rate_Hz = 1.0 / float(np.median(np.diff(t)))
    b, a = butter(2, 15.0 / (0.5 * rate_Hz))
    velocity = np.gradient(filtfilt(b, a, x), t)
    if np.corrcoef(f, velocity)[0, 1] < 0:
        f = -f  # the logs' sign conventions differ: make the force grow with the velocity (dissipative)
    top = float(np.quantile(np.abs(velocity), 0.97))
    edges = np.linspace(-top, top, 2 * bins + 1)
    centres, medians = [], []
    for lo, hi in itertools.pairwise(edges):
        inside = (velocity >= lo) & (velocity < hi)
        if np.count_nonzero(inside) >= 10:
            centres.append(float(np.median(velocity[inside])))
            medians.append(float(np.median(f[inside])))
    centres_v = v = np.array(centres)
    f_table = isotonic_regression(np.array(medians)).x
    gas = float(np.interp(0.0, v, f_table))  # the gas spring's force, carried at zero velocity
    keep = np.abs(v) > 1e-3
    v = np.concatenate([v[keep & (v < 0)], [0.0], v[keep & (v > 0)]])
    f_table = np.concatenate(
        [f_table[keep & (centres_v < 0)] - gas, [0.0], f_table[keep & (centres_v > 0)] - gas]
    )
    # isotonic medians can tie: a small viscous term keeps the table strictly increasing (and invertible)
    f_table = f_table + 50.0 * v
    return TableDamper(f"FSAE dyno {log.split('_')[2]}", v, f_table)


@dataclass(frozen=True)
class ValveSide:
    """One direction of a valve damper, in force and velocity units (pressure × piston area, flow / area).

    The bleed orifice loses pressure laminarly and turbulently, F = bleed_linear·v + bleed_quadratic·v²
    (linear at low speed, growing with the square at higher); the blow-off valve cracks at crack_N and
    passes v = valve_gain·(F − crack_N)·√F beside it (opening area ∝ excess force, flow ∝ area·√Δp)."""

    bleed_linear_Ns_per_m: float
    bleed_quadratic_Ns2_per_m2: float
    crack_N: float
    valve_gain: float

    def velocity(self, force_N: np.ndarray) -> np.ndarray:
        a, b = self.bleed_linear_Ns_per_m, self.bleed_quadratic_Ns2_per_m2
        bleed = 2.0 * force_N / (a + np.sqrt(a * a + 4.0 * b * force_N))  # root of b·v² + a·v = F
        opening = np.clip(force_N - self.crack_N, 0.0, None)
        return bleed + self.valve_gain * opening * np.sqrt(force_N)


def valve_damper(
    extension: ValveSide, compression: ValveSide, top_velocity_m_s: float = 1.5, points: int = 40
) -> TableDamper:
    """Tabulate the valve model: forces on a grid per direction, their velocities, up to
    top_velocity_m_s; the table is then smoothed like any other."""
    sides = []
    for side, sign in ((compression, -1.0), (extension, 1.0)):
        high = 100.0
        while side.velocity(np.array([high]))[0] < top_velocity_m_s:
            high *= 1.25
        force = np.linspace(0.0, high, points + 1)[1:]
        sides.append((sign * side.velocity(force), sign * force))
    (vc, fc), (ve, fe) = sides
    velocity = np.concatenate([vc[::-1], [0.0], ve])
    force = np.concatenate([fc[::-1], [0.0], fe])
    return TableDamper("valve model", velocity, force)
