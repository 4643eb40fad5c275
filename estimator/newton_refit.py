"""Re-solving the paper's objective from a nearby optimum by Newton's method: the confidence bands' bias
allowances (estimator.uncertainty) identify the same recording twice more, on a refined damper grid and with
a lower kinematics cutoff, and each optimum lies close to the one already found.

Why Newton and not IRLS. GF(θ) = Σ_i ||r_i(θ)||, r_i = A_i θ + c_i, is smooth wherever no residual vanishes
(with noise, none does), with gradient Σ_i A_iᵀ u_i (u_i = r_i/||r_i||) and Hessian
Σ_i A_iᵀ (I − u_i u_iᵀ) A_i / ||r_i|| (the sandwich's bread). IRLS (estimator.solvers.exact) converges
linearly: from a nearby start it still needs 15-20 weighted normal matrices to meet its tolerance. Newton's
method converges quadratically from there: 2-4 Hessians of the same cost. Every step is checked: GF must
fall (the step is halved until it does, and the iteration stops when it cannot), so it never ends worse
than it started.

ϑ. When the tyre's relaxation time was identified, log τ is one more unknown: only the tyre column g(τ)
depends on it, r_i = A_i(τ) θ + c_i, so its derivatives are C_d·∂g/∂log τ and C_d·∂²g/∂log τ² (central
differences) and the mixed term with C_d is ∂g/∂log τ; the Hessian is exact in (θ, log τ).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.equations import TYRE_DAMPING, LinearResiduals, maxwell_regressor
from estimator.linear_algebra import cholesky_factor, cholesky_solve
from estimator.order_statistics import median
from estimator.vehicle import coefficient_from_relaxation_time, relaxation_time_from_coefficient

LOG_TAU_STEP = 1e-3
"""Central-difference step on log τ for the tyre column's derivatives."""
MAX_NEWTON_ITERATIONS = 30
MAX_HALVINGS = 30


@dataclass(frozen=True)
class NewtonRefit:
    theta: np.ndarray
    """The optimum's θ, in the system's unknowns."""
    relaxation_time_s: float | None
    """τ at the optimum when it was an unknown, else None."""
    objective: float
    iterations: int


def hessian_factors(columns: np.ndarray, unit: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """GF's Hessian in the coefficients of `columns` (p, e, n), Σᵢ Aᵢᵀ(I − uᵢuᵢᵀ)Aᵢ / ||rᵢ||, as
    flat·flatᵀ − along·alongᵀ: flat (p, e·n) the columns over √||rᵢ|| (root), along (p, n) uᵢᵀAᵢ / √||rᵢ||
    (unit: the residuals over their norms, (e, n)). Two sets' cross block is flat₁·flat₂ᵀ − along₁·along₂ᵀ."""
    along = np.einsum("pen,en->pn", columns, unit) / root
    return (columns / root).reshape(columns.shape[0], -1), along


class _Problem:
    """GF and its derivatives over z = (θ scaled by its columns' norms[, log τ]).

    The scaled matrix is held transposed, one row per unknown (p, e·n): the Hessian's products then run
    along the samples, where numpy's inner loops are long (along the few unknowns they are not)."""

    def __init__(self, system: LinearResiduals, free_tau: bool) -> None:
        self.system = system
        e, n, p = system.matrix.shape
        self.equations, self.samples, self.parameters = e, n, p
        flat = system.matrix.reshape(e * n, p)  # equation-major rows, as the system stores them
        self.scale = np.linalg.norm(flat, axis=0)
        self.scale[self.scale == 0] = 1.0
        self.rows = np.ascontiguousarray(flat.T)
        self.rows /= self.scale[:, None]
        self.offset = system.offset.reshape(e * n)
        self.free_tau = free_tau and system.tyre_theta is not None and bool(system.tyre_rates_m_s)
        self.dt = system.filters.sample_time_s
        if self.free_tau:
            self.column = system.parameter_names.index(TYRE_DAMPING)
            self.log_tau0 = float(np.log(relaxation_time_from_coefficient(float(system.tyre_theta), self.dt)))

    def tyre(self, log_tau: float) -> np.ndarray:
        """The tyre column (e·n,) at τ = exp(log_tau), unscaled."""
        theta = coefficient_from_relaxation_time(float(np.exp(log_tau)), self.dt)
        column = np.zeros((self.equations, self.samples))
        for rate, equation in zip(self.system.tyre_rates_m_s, self.system.tyre_equations, strict=True):
            column[equation] = maxwell_regressor(rate, theta)[self.system.sample_index]
        return column.reshape(-1)

    def matrix_rows(self, log_tau: float | None) -> np.ndarray:
        """The scaled matrix, transposed (p, e·n), its tyre row at τ = exp(log_tau) when τ is free."""
        if log_tau is None or not self.free_tau:
            return self.rows
        rows = self.rows.copy()
        rows[self.column] = self.tyre(log_tau) / self.scale[self.column]
        return rows

    def objective(self, z: np.ndarray) -> float:
        theta, log_tau = self.split(z)
        r = (theta @ self.matrix_rows(log_tau) + self.offset).reshape(self.equations, -1)
        return float(np.sqrt(np.square(r).sum(axis=0)).sum())

    def split(self, z: np.ndarray) -> tuple[np.ndarray, float | None]:
        return (z[:-1], float(z[-1])) if self.free_tau else (z, None)

    def newton_step(self, z: np.ndarray) -> np.ndarray:
        """The Newton step at z."""
        theta, log_tau = self.split(z)
        rows = self.matrix_rows(log_tau)
        e = self.equations
        r = (theta @ rows + self.offset).reshape(e, -1)
        norms = np.sqrt(np.square(r).sum(axis=0))
        norms = np.maximum(norms, 1e-9 * max(float(median(norms)), 1e-300))
        unit = r / norms
        columns = rows.reshape(rows.shape[0], e, -1)  # (p, e, n)
        second: list[tuple[int, int, float]] = []
        if self.free_tau:
            up, mid, down = (self.tyre(log_tau + s) for s in (LOG_TAU_STEP, 0.0, -LOG_TAU_STEP))
            slope = ((up - down) / (2 * LOG_TAU_STEP)).reshape(e, -1)
            curvature = ((up - 2 * mid + down) / LOG_TAU_STEP**2).reshape(e, -1)
            damping = theta[self.column] / self.scale[self.column]
            columns = np.concatenate([columns, (damping * slope)[None]], axis=0)
            tau_index = columns.shape[0] - 1
            # second derivatives of r: ∂²r/∂log τ² = C_d·g'', ∂²r/∂log τ ∂z_C = g'/scale_C
            second = [
                (tau_index, tau_index, float(np.sum(unit * damping * curvature))),
                (tau_index, self.column, float(np.sum(unit * slope)) / self.scale[self.column]),
            ]
        gradient = columns.reshape(columns.shape[0], -1) @ unit.reshape(-1)
        root = np.sqrt(norms)
        if e == 2:  # I − u uᵀ = v vᵀ with v ⟂ u: one row per sample instead of two
            across = columns[:, 1] * (unit[0] / root) - columns[:, 0] * (unit[1] / root)
            hessian = across @ across.T
        else:
            flat, along = hessian_factors(columns, unit, root)
            hessian = flat @ flat.T - along @ along.T
        for i, j, value in second:
            hessian[i, j] += value
            if i != j:
                hessian[j, i] += value
        try:
            return -cholesky_solve(cholesky_factor(hessian), gradient)
        except np.linalg.LinAlgError:
            return -np.linalg.lstsq(hessian, gradient, rcond=None)[0]

    def theta(self, z: np.ndarray) -> tuple[np.ndarray, float | None]:
        theta, log_tau = self.split(z)
        return theta / self.scale, (float(np.exp(log_tau)) if log_tau is not None else None)


def newton_refit(
    system: LinearResiduals,
    initial: np.ndarray,
    relaxation_time_bounds_s: tuple[float, float] | None = None,
    tolerance: float = 1e-10,
) -> NewtonRefit:
    """Minimise GF of `system` starting from θ = `initial` (a nearby optimum) by damped Newton steps (module
    docstring). relaxation_time_bounds_s: τ is an unknown too, starting at the system's ϑ and kept within
    these bounds (None: ϑ stays as the system has it). Stops when a step lowers GF by less than `tolerance`
    (relative) or no halving of it lowers GF."""
    problem = _Problem(system, relaxation_time_bounds_s is not None)
    z = np.asarray(initial, dtype=float) * problem.scale
    bounds = np.log(relaxation_time_bounds_s) if relaxation_time_bounds_s is not None else None
    if problem.free_tau:
        z = np.append(z, problem.log_tau0)
    objective = problem.objective(z)
    iterations = 0
    for iterations in range(1, MAX_NEWTON_ITERATIONS + 1):  # noqa: B007
        step = problem.newton_step(z)
        length, improved = 1.0, False
        for _ in range(MAX_HALVINGS):
            trial = z + length * step
            if problem.free_tau and bounds is not None:
                trial[-1] = float(np.clip(trial[-1], *bounds))
            value = problem.objective(trial)
            if value < objective:
                improved = True
                break
            length *= 0.5
        if not improved:
            break
        gain = objective - value
        z, objective = trial, value
        if gain <= tolerance * objective:
            break
    theta, tau = problem.theta(z)
    return NewtonRefit(theta, tau, objective, iterations)
