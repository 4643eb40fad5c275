"""How a vehicle's damping has changed from test to test: the damper force at a few reference velocities,
read off each test's identified curve, and its change since the first test.

The force at a reference velocity is interpolated linearly between the curve's points (the curve itself is
piecewise linear, estimator.identify); outside the velocities the curve spans it is None: a sweep that did
not reach 0.5 m/s says nothing about the damper there, and extrapolating would invent a trend.

The change is relative to the oldest test whose curve reaches that velocity (per corner and velocity):
100·(F − F_first)/F_first in %, i.e. 100·(F/F_first − 1); None where the force is None or F_first is 0.
Dividing by the signed first force makes a damper that wears out (less force at the same velocity) show a
negative change on both sides, rebound (v > 0, F > 0) and compression (v < 0, F < 0) alike.

Pure: numbers in, numbers out (no I/O).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

REFERENCE_VELOCITIES_M_S: tuple[float, ...] = (-0.5, -0.3, -0.1, 0.1, 0.3, 0.5)
"""Damper velocities (m/s, positive = rebound/extension) at which the trend compares the tests."""

Curve = tuple[Sequence[float], Sequence[float]]
"""A damper curve: (velocities in m/s, ascending; forces in N at those velocities)."""


def force_at(curve: Curve, velocities_m_s: Sequence[float]) -> list[float | None]:
    """The curve's force (N) at each velocity (m/s), linear between its points; None outside its range
    (and for a curve without points)."""
    velocity = np.asarray(curve[0], dtype=float)
    force = np.asarray(curve[1], dtype=float)
    if velocity.size == 0 or velocity.size != force.size:
        return [None] * len(velocities_m_s)
    low, high = float(velocity.min()), float(velocity.max())
    order = np.argsort(velocity, kind="stable")
    return [
        float(np.interp(v, velocity[order], force[order])) if low <= v <= high else None
        for v in velocities_m_s
    ]


def change_percent(force_N: float | None, first_N: float | None) -> float | None:
    """100·(force − first)/first (%): negative when the force's magnitude fell (on either side of zero
    velocity); None when either is None or first is 0."""
    if force_N is None or first_N is None or first_N == 0:
        return None
    change = 100.0 * (force_N - first_N) / first_N
    return change if change != 0 else 0.0  # never -0.0 (a compression side's own first test)


@dataclass(frozen=True)
class TrendPoint:
    """One test's damping at the reference velocities, for one corner."""

    test: int
    """Index of the test in the sequence given to damping_trend (oldest first)."""
    force_N: tuple[float | None, ...]
    """Force at each reference velocity (N); None outside the curve's range."""
    change_percent: tuple[float | None, ...]
    """Change since the first test that reaches that velocity (%); None where not comparable."""


@dataclass(frozen=True)
class CornerTrend:
    corner: str
    """single (quarter car), or left / right (axle)."""
    points: tuple[TrendPoint, ...]
    """The tests that have a curve for this corner, oldest first."""


def damping_trend(
    tests: Sequence[Mapping[str, Curve]],
    reference_m_s: Sequence[float] = REFERENCE_VELOCITIES_M_S,
) -> list[CornerTrend]:
    """The trend of each corner over `tests` (oldest first; each maps corner -> its curve, empty for a test
    without an identification). Corners in the order they first appear."""
    corners: list[str] = []
    for curves in tests:
        corners += [corner for corner in curves if corner not in corners]
    trends = []
    for corner in corners:
        first: list[float | None] = [None] * len(reference_m_s)
        points = []
        for index, curves in enumerate(tests):
            if corner not in curves:
                continue
            forces = force_at(curves[corner], reference_m_s)
            first = [f if f is not None else forces[i] for i, f in enumerate(first)]
            changes = tuple(change_percent(f, first[i]) for i, f in enumerate(forces))
            points.append(TrendPoint(index, tuple(forces), changes))
        trends.append(CornerTrend(corner, tuple(points)))
    return trends
