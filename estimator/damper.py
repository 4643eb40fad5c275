"""Damper force-velocity curves: the piecewise-linear curve the estimator identifies (points C_a^1..C_a^N on
a velocity grid, linear between them) and the hyperbolic-tangent model of the paper's eq (10).

Velocity is v = ẋ_s - ẋ_t (extension positive); force is the damper force on the wheel, positive in
extension, so a dissipative damper has force·velocity >= 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.errors import InvalidValueError
from estimator.order_statistics import quantile

GRID_QUANTILE = 0.002
"""The damper velocity grid spans the measured suspension velocities from this quantile to 1 − it; the end
segments extend linearly beyond, so the few samples outside still count."""


def velocity_grid(velocity_m_s: np.ndarray, points: int) -> np.ndarray:
    """`points` evenly spaced knots over the suspension velocities measured (GRID_QUANTILE each end): the
    grid the damper curve is identified on."""
    lo, hi = quantile(velocity_m_s, [GRID_QUANTILE, 1.0 - GRID_QUANTILE])
    if not hi > lo:
        raise InvalidValueError(
            "the suspension barely moved: no velocity range to identify a damper curve on"
        )
    return np.linspace(lo, hi, points)


def hat_basis(velocity_m_s: np.ndarray, grid_m_s: np.ndarray) -> np.ndarray:
    """Basis of linear interpolation on `grid_m_s`: column j is the tent function of grid point j, so that
    force = basis @ points. Outside the grid the two end segments extend linearly."""
    v = np.asarray(velocity_m_s, dtype=float)
    g = np.asarray(grid_m_s, dtype=float)
    seg = np.clip(np.searchsorted(g, v, side="right") - 1, 0, len(g) - 2)
    w = (v - g[seg]) / (g[seg + 1] - g[seg])
    basis = np.zeros((v.size, g.size), order="F")  # column-major: each column's samples contiguous, as the
    rows = np.arange(v.size)  # zero-phase filter (estimator.digital_filters) runs along them
    basis[rows, seg] = 1.0 - w.ravel()
    basis[rows, seg + 1] = w.ravel()
    return basis


@dataclass(frozen=True)
class PiecewiseLinearCurve:
    """Force points on a strictly increasing velocity grid; linear between points, linear extension beyond."""

    velocity_m_s: np.ndarray
    force_N: np.ndarray

    def __post_init__(self) -> None:
        v = np.asarray(self.velocity_m_s, dtype=float)
        f = np.asarray(self.force_N, dtype=float)
        if v.ndim != 1 or v.shape != f.shape or v.size < 2:
            raise InvalidValueError(
                "a piecewise-linear curve needs matching 1-D velocity and force arrays of >= 2 points"
            )
        if np.any(np.diff(v) <= 0):
            raise InvalidValueError("curve velocities must be strictly increasing")
        object.__setattr__(self, "velocity_m_s", v)
        object.__setattr__(self, "force_N", f)

    def force(self, velocity_m_s: np.ndarray | float) -> np.ndarray:
        v = np.asarray(velocity_m_s, dtype=float)
        g, f = self.velocity_m_s, self.force_N
        inside = np.interp(v, g, f)
        below = (f[1] - f[0]) / (g[1] - g[0]) * np.minimum(v - g[0], 0.0)
        above = (f[-1] - f[-2]) / (g[-1] - g[-2]) * np.maximum(v - g[-1], 0.0)
        return inside + below + above

    def resampled(self, velocity_m_s: np.ndarray) -> PiecewiseLinearCurve:
        """The same curve on another grid (exact where the new grid contains the old knots)."""
        return PiecewiseLinearCurve(velocity_m_s, self.force(velocity_m_s))

    def dissipative(self) -> PiecewiseLinearCurve:
        """The curve to simulate: extended beyond its end knots with its end slopes where they are not
        negative and flat where they are (see dissipative_table)."""
        velocity, force = dissipative_table(self.velocity_m_s, self.force_N)
        return PiecewiseLinearCurve(velocity, force)


@dataclass(frozen=True)
class TanhCurve:
    """Paper eq (10): f = c_s·v + κ·(tanh(μ·v + β) − tanh(β)).

    c_s: linear (high-speed) damping, N·s/m; kappa: κ, the tanh force scale, N; mu: μ, s/m, how fast the
    valve opens; beta: β, the asymmetry between extension and compression (dimensionless). f(0) = 0.
    """

    c_s: float
    kappa: float
    mu: float
    beta: float

    def force(self, velocity_m_s: np.ndarray | float) -> np.ndarray:
        v = np.asarray(velocity_m_s, dtype=float)
        return self.c_s * v + self.kappa * (np.tanh(self.mu * v + self.beta) - np.tanh(self.beta))

    def slope_at_zero(self) -> float:
        """df/dv at v = 0, N·s/m."""
        return self.c_s + self.kappa * self.mu * (1.0 - np.tanh(self.beta) ** 2)

    def as_dict(self) -> dict[str, float]:
        return {"c_s": self.c_s, "kappa": self.kappa, "mu": self.mu, "beta": self.beta}


def dissipative_table(velocity_m_s: np.ndarray, force_N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Knots and forces of piecewise-linear curves (force_N of shape (grid,) or (grid, batch)) with one more
    knot a grid span beyond each end, where each curve goes on with its end slope if that is not negative and
    flat if it is; linear beyond those knots, the table is that extension everywhere. A damper's force does
    not fall back as the suspension moves faster than the sweep made it. A curve fitted to the few samples
    at its ends can slope back there, and its linear extension then turns into a force that pushes with the
    motion, so a simulated model runs away once it passes the end knots (independent world, a car at 2 ms
    with 351 N of friction and a body laser lagging 4.8 ms: the doctor's model with the delay had an end
    slope of -8611 N·s/m and diverged; extended flat, its gap was 445 µm against the current model's
    644 µm). Every simulation of an identified or diagnosed curve uses it (estimator.output_error,
    estimator.doctor.simulation), so that validate and the doctor simulate the same model."""
    velocity = np.asarray(velocity_m_s, dtype=float)
    force = np.asarray(force_N, dtype=float)
    span = velocity[-1] - velocity[0]
    low = np.maximum((force[1] - force[0]) / (velocity[1] - velocity[0]), 0.0)
    high = np.maximum((force[-1] - force[-2]) / (velocity[-1] - velocity[-2]), 0.0)
    knots = np.concatenate([[velocity[0] - span], velocity, [velocity[-1] + span]])
    forces = np.concatenate([[force[0] - low * span], force, [force[-1] + high * span]])
    return knots, forces


class CurveBatch:
    """Several piecewise-linear curves on one common velocity grid, evaluated together: column b of
    `force_N` (shape (n_grid, batch)) is curve b. force(v) takes v of shape (batch,) and returns the force
    of each curve at its own velocity. Used to integrate a population of models at once."""

    def __init__(self, velocity_m_s: np.ndarray, force_N: np.ndarray) -> None:
        self.velocity_m_s = np.asarray(velocity_m_s, dtype=float)
        self.force_N = np.asarray(force_N, dtype=float)
        self._columns = np.arange(self.force_N.shape[1])
        # segment j runs from knot j to j+1; searching the interior knots gives it without clipping, and
        # the end segments extend linearly
        self._interior = self.velocity_m_s[1:-1]
        self._slopes = np.diff(self.force_N, axis=0) / np.diff(self.velocity_m_s)[:, None]

    def dissipative(self) -> CurveBatch:
        """Every curve extended as PiecewiseLinearCurve.dissipative extends one."""
        return CurveBatch(*dissipative_table(self.velocity_m_s, self.force_N))

    def force(self, velocity_m_s: np.ndarray) -> np.ndarray:
        seg = np.searchsorted(self._interior, velocity_m_s, side="right")
        return (
            self.force_N[seg, self._columns]
            + (velocity_m_s - self.velocity_m_s[seg]) * self._slopes[seg, self._columns]
        )


LOW_SPEED_CLEARANCE = 0.5
"""A uniform knot closer to a low-speed knot than this share of the low-speed knots' spacing gives way."""


def low_speed_grids(grids: list[np.ndarray], knots_m_s: tuple[float, ...]) -> list[np.ndarray]:
    """Damper grids with knots at ±knots_m_s added (those inside; the model doctor resolves its curve near
    zero velocity so), the uniform knots too close to them dropped (not the end knots), then made the same
    size (an axle's two curves must be)."""
    extra = np.unique(np.concatenate([-np.asarray(knots_m_s), knots_m_s]))
    clearance = LOW_SPEED_CLEARANCE * float(np.min(np.diff(extra)))
    changed = []
    for grid in grids:
        inside = extra[(extra > grid[0]) & (extra < grid[-1])]
        distance = np.min(np.abs(grid[:, None] - inside[None, :]), axis=1, initial=np.inf)
        ends = (grid == grid[0]) | (grid == grid[-1])
        changed.append(np.unique(np.concatenate([grid[(distance >= clearance) | ends], inside])))
    size = max(g.size for g in changed)
    for k, grid in enumerate(changed):
        while grid.size < size:  # the widest interval halved
            widest = int(np.argmax(np.diff(grid)))
            grid = np.insert(grid, widest + 1, 0.5 * (grid[widest] + grid[widest + 1]))
        changed[k] = grid
    return changed
