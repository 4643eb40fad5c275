"""95% confidence intervals of the identified unknowns (masses, tyre damping, free stiffnesses, every damper
curve point), from the sandwich covariance of the paper's objective at its optimum with a long-run
(heteroscedasticity- and autocorrelation-consistent) variance of the score.

Why this method. GF(θ) = Σ_i ||r_i(θ)|| with r_i = A_i θ + c_i is an M-estimator: the optimum solves
Σ_i ψ_i(θ) = 0 with the score ψ_i = A_iᵀ u_i, u_i = r_i/||r_i||. Its asymptotic covariance is the sandwich
H⁻¹ V H⁻¹ with the bread H = Σ_i A_iᵀ (I − u_i u_iᵀ) A_i / ||r_i|| (the Hessian of GF: the IRLS normal
matrix AᵀWA minus the part along each residual's own direction) and the meat V the variance of Σ_i ψ_i.
The residuals are strongly correlated in time: every column of the equations passes the same low-pass
(estimator.signals), the selected samples are a few milliseconds apart, and what is left of the model error
repeats with the sweep. Treating the scores as independent would make the bands several times too narrow.
V is therefore the long-run variance of the score series, estimated by overlapping blocks (the
Bartlett-kernel Newey-West estimator): with S_j the sum of the scores over a window of L consecutive
selected samples, V = n/(L·(n−L+1))·Σ_j S_j S_jᵀ, and L spans several correlation lengths of the
residual (BLOCK_EQUATION_PERIODS periods of the equation low-pass's cutoff, at least MIN_BLOCK_S). This is a
closed form at the optimum: one pass over the residuals, no re-solve, so the identification costs a few
per cent more, where a block bootstrap re-solving the convex problem a few dozen times would cost a few
dozen times as much (see BENCHMARKS.md, "Confidence bands").

ϑ. When the tyre's relaxation time was identified (estimator.relaxation), log τ is one more unknown of the
linearised problem: its column is C_d·∂g/∂log τ (central difference of the tyre column), so the bands of
the others carry the uncertainty of ϑ as well; τ's own interval is not reported.

Bias allowances. At 5 µm noise the noise-driven widths are small (masses ~0.01%, stiffnesses ~0.1-0.3%)
and two systematic errors of the method are of the same size or larger; each gets an allowance from a
second identification (a Richardson-style estimate, combined in quadrature with the noise width):
the curve's representation bias (representation_bias, below), and the bias of the velocities' low-pass
(filter_bias): the same identification with the kinematics cutoff lowered to KINEMATICS_CUTOFF_RATIO of it.
The two extra solves cost more than the sandwich itself (BENCHMARKS.md); both start from the optimum
already found. The filter's optimum lies close to it and is reached by Newton steps (estimator.newton_refit),
3-4 times faster than IRLS from scratch, with the same optimum (within 0.1% of the noise half-width on the
tests' cases). The refined grid's can lie far (GF 30% lower where the curve has a sharp knee), where Newton
alone takes many halved steps: that one is solved by the exact solver (a few IRLS iterations handing over
to Newton) from the same start.

The curve's representation bias: The damper curve is piecewise linear between its grid points, and the
true curve is not: the identified point at a grid velocity is (roughly) the best piecewise-linear fit of the
curve around it, not the curve's value there. Near a sharp knee (e.g. at 0 m/s) that representation bias
can exceed the noise-driven width. The tests and the coverage benchmark compare the band at each grid point
with the true force at that velocity, so this bias counts against the coverage they report.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from estimator.equations import TYRE_DAMPING, LinearResiduals, maxwell_regressor
from estimator.order_statistics import median
from estimator.signals import FilterChoice
from estimator.solvers.exact import solve_exact
from estimator.vehicle import coefficient_from_relaxation_time, relaxation_time_from_coefficient

CONFIDENCE = 0.95
Z_95 = 1.959963984540054
"""Two-sided 95% quantile of the normal distribution."""
BLOCK_EQUATION_PERIODS = 10.0
"""Block length in periods of the equation low-pass's cutoff (the residual's correlation time is about one
to two periods of it)."""
MIN_BLOCK_S = 0.1
RICHARDSON_FACTOR = 2.0
"""Representation bias allowance = this × |coarse − refined|: by Richardson's argument a grid error that
falls as h^k is (coarse − refined)·2^k/(2^k − 1); k = 1 (a kink between grid points, the worst case of a
piecewise-linear curve) gives 2, k = 2 (a smooth bend) 4/3."""
KINEMATICS_CUTOFF_RATIO = 0.8
KINEMATICS_RICHARDSON = 1.0 / (KINEMATICS_CUTOFF_RATIO**-2 - 1.0)
"""Kinematics filter bias allowance = this × |θ − θ at KINEMATICS_CUTOFF_RATIO × the cutoff|: the
velocities in the damper and tyre terms come from a low-pass, whose bias falls about as cutoff⁻² (on the
simulated sweeps: lowering it by 0.8 moved the stiffnesses by 0.55 of their error, 0.8⁻² − 1 = 0.56), so the
bias at the chosen cutoff is the difference / (0.8⁻² − 1) ≈ 1.8 × it (Richardson)."""
LOG_TAU_STEP = 1e-3
"""Central-difference step on log τ for the tyre column's derivative."""


@dataclass(frozen=True)
class Intervals:
    """θ's standard errors and 95% intervals, by position in θ (as LinearResiduals.parameter_names)."""

    parameter_names: list[str]
    theta: np.ndarray
    standard_error: np.ndarray
    covariance: np.ndarray
    block_s: float
    """The long-run variance's block length in seconds."""
    representation_bias: np.ndarray | None = None
    """|θ − θ on the grid with every interval halved| by unknown (representation_bias), or None."""

    @property
    def half_width(self) -> np.ndarray:
        """z·σ, combined with the representation bias allowance b as sqrt((z·σ)² + b²) when there is one."""
        noise = Z_95 * self.standard_error
        if self.representation_bias is None:
            return noise
        return np.hypot(noise, self.representation_bias)

    @property
    def low(self) -> np.ndarray:
        return self.theta - self.half_width

    @property
    def high(self) -> np.ndarray:
        return self.theta + self.half_width

    def with_bias(self, bias: np.ndarray) -> Intervals:
        return Intervals(
            self.parameter_names, self.theta, self.standard_error, self.covariance, self.block_s, bias
        )

    def interval(self, name: str) -> tuple[float, float] | None:
        """[low, high] of the unknown called `name` (None when θ has no such unknown)."""
        if name not in self.parameter_names:
            return None
        index = self.parameter_names.index(name)
        return float(self.low[index]), float(self.high[index])


def _tau_column(system: LinearResiduals, theta: np.ndarray, sample_time_s: float) -> np.ndarray | None:
    """∂r/∂log τ (e, n) at θ for the Maxwell tyre column, None when the system has no ϑ."""
    if system.tyre_theta is None or not system.tyre_rates_m_s or system.tyre_theta == 0.0:
        return None
    tyre_damping = system.value(theta, TYRE_DAMPING) or 0.0
    tau = relaxation_time_from_coefficient(system.tyre_theta, sample_time_s)
    column = np.zeros(system.matrix.shape[:2])
    for rate, equation in zip(system.tyre_rates_m_s, system.tyre_equations, strict=True):
        up, down = (
            maxwell_regressor(rate, coefficient_from_relaxation_time(tau * np.exp(s), sample_time_s))
            for s in (LOG_TAU_STEP, -LOG_TAU_STEP)
        )
        column[equation] = tyre_damping * (up - down)[system.sample_index] / (2 * LOG_TAU_STEP)
    return column


def confidence_intervals(
    system: LinearResiduals,
    theta: np.ndarray,
    sample_time_s: float,
    relaxation_time_identified: bool = False,
) -> Intervals:
    """Sandwich covariance of θ at the optimum of GF with a block long-run variance of the score (module
    docstring). relaxation_time_identified: add log τ as an unknown of the linearised problem."""
    matrix = system.matrix  # (e, n, p)
    residual = system.residuals(theta)  # (e, n)
    if relaxation_time_identified:
        extra = _tau_column(system, theta, sample_time_s)
        if extra is not None:
            matrix = np.concatenate([matrix, extra[:, :, None]], axis=2)
    e, n, p = matrix.shape
    norms = np.linalg.norm(residual, axis=0)
    norms = np.maximum(norms, 1e-9 * max(float(median(norms)), 1e-300))
    unit = residual / norms
    score = np.einsum("enp,en->np", matrix, unit)  # ψ_i, (n, p)
    scaled = matrix / np.sqrt(norms)[None, :, None]
    flat = scaled.reshape(e * n, p)
    bread = flat.T @ flat - (score / norms[:, None]).T @ score
    spacing_s = float(median(np.diff(system.sample_index))) * sample_time_s
    block_s = max(BLOCK_EQUATION_PERIODS / system.filters.equation_cutoff_Hz, MIN_BLOCK_S)
    length = int(np.clip(round(block_s / spacing_s), 1, max(n // 4, 1)))
    cumulative = np.vstack([np.zeros((1, p)), np.cumsum(score, axis=0)])
    windows = cumulative[length:] - cumulative[:-length]  # (n − L + 1, p)
    meat = windows.T @ windows * (n / (length * windows.shape[0]))
    # scale to unit columns so the solve is well conditioned (masses, forces and stiffnesses differ by 1e5)
    scale = np.sqrt(np.abs(np.diag(bread)))
    scale[scale == 0] = 1.0
    inverse = np.linalg.pinv(bread / np.outer(scale, scale)) / np.outer(scale, scale)
    covariance = inverse @ meat @ inverse
    covariance = covariance[: system.n_params, : system.n_params]
    standard_error = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return Intervals(
        list(system.parameter_names), np.asarray(theta, float), standard_error, covariance, length * spacing_s
    )


def refined_grids(system: LinearResiduals) -> list[np.ndarray]:
    """Each damper grid with a point added midway in every interval (the old points stay grid points)."""
    return [np.linspace(grid[0], grid[-1], 2 * grid.size - 1) for grid in system.grids_m_s]


def refined_start(system: LinearResiduals, theta: np.ndarray, refined: LinearResiduals) -> np.ndarray:
    """θ of `system` carried onto `refined` (refined_grids): the same curve (old points kept, midpoints on
    the straight line between them, so the curve and GF are unchanged) and the other unknowns by name: the
    refined optimum is found from there by the exact solver (estimator.solvers.exact)."""
    start = np.zeros(refined.n_params)
    in_curves = np.zeros(refined.n_params, bool)
    for coarse_slice, fine_slice, grid, fine_grid in zip(
        system.curve_slices, refined.curve_slices, system.grids_m_s, refined.grids_m_s, strict=True
    ):
        start[fine_slice] = np.interp(fine_grid, grid, theta[coarse_slice])
        in_curves[fine_slice] = True
    for index, name in enumerate(refined.parameter_names):
        if not in_curves[index]:
            start[index] = theta[system.parameter_names.index(name)]
    return start


def representation_bias(system: LinearResiduals, theta: np.ndarray, refined: LinearResiduals) -> np.ndarray:
    """RICHARDSON_FACTOR·|θ − θ_refined| by unknown of `system`: θ_refined is the same identification on
    the grid with halved intervals (`refined`, built on refined_grids(system) with the same filters and
    samples), compared at the shared unknowns (masses, tyre damping, stiffnesses) and at the original grid
    points. Where the true curve bends between grid points (a knee at 0 m/s) the two differ by about the
    coarse grid's representation error; elsewhere by noise, so the allowance is conservative there."""
    fine = solve_exact(refined, initial=refined_start(system, theta, refined), certify=False).theta
    return richardson_bias(system, theta, refined, fine)


def richardson_bias(
    system: LinearResiduals, theta: np.ndarray, refined: LinearResiduals, fine: np.ndarray
) -> np.ndarray:
    """RICHARDSON_FACTOR·|θ − fine| by unknown of `system`, `fine` being the optimum on the `refined` grid:
    curve points compared at the coarse grid's points, the other unknowns by name."""
    bias = np.zeros(system.n_params)
    in_curves = np.zeros(system.n_params, bool)
    for coarse_slice, fine_slice in zip(system.curve_slices, refined.curve_slices, strict=True):
        bias[coarse_slice] = RICHARDSON_FACTOR * np.abs(theta[coarse_slice] - fine[fine_slice][::2])
        in_curves[coarse_slice] = True
    for index, name in enumerate(system.parameter_names):
        if not in_curves[index]:
            bias[index] = RICHARDSON_FACTOR * abs(theta[index] - fine[refined.parameter_names.index(name)])
    return bias


Refit = Callable[[LinearResiduals, np.ndarray], np.ndarray]
"""(system, θ of a nearby solution to start from) -> the system's solution θ."""


def filter_bias(theta: np.ndarray, smoother: LinearResiduals, refit: Refit) -> np.ndarray:
    """|θ − θ_smoother|·KINEMATICS_RICHARDSON by unknown: θ_smoother is the same identification with the
    kinematics low-pass at KINEMATICS_CUTOFF_RATIO of its cutoff (`smoother`, same grids and samples),
    `refit` the solver (with the ϑ search when ϑ is identified), started from θ."""
    other = refit(smoother, np.asarray(theta, dtype=float))
    return KINEMATICS_RICHARDSON * np.abs(np.asarray(theta) - other)


def identification_intervals(
    system: LinearResiduals,
    theta: np.ndarray,
    sample_time_s: float,
    relaxation_time_identified: bool,
    rebuild: Callable[[list[np.ndarray], FilterChoice], LinearResiduals] | None,
    refit: Refit | None = None,
) -> Intervals:
    """The intervals `identify` reports: the sandwich (confidence_intervals), widened by the bias
    allowances when `rebuild` ((grids, filters) -> the same system on those) is given: the representation
    bias of the grid, and, with `refit` ((system, start θ) -> its solution θ), the kinematics filter's
    bias; the two combine with the noise width in quadrature."""
    intervals = confidence_intervals(system, theta, sample_time_s, relaxation_time_identified)
    if rebuild is None:
        return intervals
    bias = representation_bias(system, theta, rebuild(refined_grids(system), system.filters))
    if refit is not None:
        smoother = replace(
            system.filters, kinematics_cutoff_Hz=system.filters.kinematics_cutoff_Hz * KINEMATICS_CUTOFF_RATIO
        )
        bias = np.hypot(bias, filter_bias(theta, rebuild(system.grids_m_s, smoother), refit))
    return intervals.with_bias(bias)
