"""The tyre's Maxwell relaxation time when the vehicle file does not state ϑ: the paper's objective
minimised over the convex unknowns and ϑ together, then certified at the ϑ found.

With ϑ fixed the paper's objective GF = Σ_i ||r_i(θ)|| is convex in every other unknown θ (masses, tyre
damping, curve points, free stiffnesses) and solved exactly (estimator.solvers.exact: iteratively
reweighted least squares, IRLS). ϑ enters nonlinearly, only through the tyre column g(ϑ) (δ̇ through the
Maxwell element; estimator.equations). The search runs on log τ, τ = Δt·ϑ/(1−ϑ) the relaxation time,
within RELAXATION_TIME_BOUNDS_S, because ϑ crowds against 1 where real tyres lie (τ of 20-50 ms is ϑ of
0.95-0.98 at 1 ms) and because τ, unlike ϑ, does not depend on the sample time.

Method: IRLS extended by ϑ. IRLS is a majorise-minimise scheme: with weights w_i = 1/||r_i|| at the current
point, ½·Σ_i (w_i·||r_i||² + 1/w_i) lies above GF everywhere and touches it there, so any point that lowers
this weighted least-squares majoriser lowers GF. Each iteration here minimises the majoriser over θ and τ
together: for a trial τ only the tyre column changes, the weighted normal equations of the other columns
are formed once per iteration, and the weighted least-squares optimum for that τ costs one product with the
new column and a small solve, so a bounded Brent search (scipy.optimize.minimize_scalar) over log τ is cheap.
The current τ is kept when the search does not beat it, so GF never increases; the iteration stops when GF
improves by less than `tolerance` (relative). It converges to a stationary point of GF over (θ, τ); in
every case of the tests the profile min_θ GF(θ, τ) was unimodal over the bounds, and the first iteration
searches the whole range. The result is then solved by the exact solver at the τ found and certified by its
dual bound: the certificate is that of the convex problem at the identified ϑ (the search over ϑ itself
carries none).

Cost: one weighted normal matrix per iteration, as plain IRLS, plus about a dozen column products per
iteration for the search, instead of a dozen full convex solves for a nested search. IRLS converges
linearly (about 16 iterations to 1e-8 on the benchmark's recording), so once an iteration gains less than
NEWTON_HANDOVER (relative) the rest is done by exact Newton steps over (θ, log τ) (estimator.newton_refit,
quadratic convergence, every step checked to lower GF): 3 IRLS iterations and a few Newton steps reach the
same optimum, to a lower GF than IRLS's own stopping point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.equations import TYRE_DAMPING, LinearResiduals, maxwell_regressor
from estimator.linear_algebra import cholesky_factor, cholesky_solve
from estimator.newton_refit import newton_refit
from estimator.order_statistics import median
from estimator.solvers.exact import NEWTON_HANDOVER, ExactSolution, solve_exact
from estimator.vehicle import coefficient_from_relaxation_time, relaxation_time_from_coefficient

RELAXATION_TIME_BOUNDS_S = (0.002, 0.25)
"""Search range of τ = C_d/K_d: ϑ at 1 ms from 0.67 to 0.996 (the paper's tyre: ϑ = 0.97, τ = 32 ms)."""
FIRST_TOLERANCE = 1e-3
"""Brent's tolerance on log τ in the first iteration, which searches the whole range (0.1% in τ)."""
LOCAL_WIDTH = 0.1
MIN_WIDTH = 1e-3
"""Later iterations step τ by a parabola through log τ and log τ ± a width: the last step's size, clipped to
[MIN_WIDTH, LOCAL_WIDTH]."""


@dataclass(frozen=True)
class RelaxationFit:
    relaxation_time_s: float
    system: LinearResiduals
    """The system with the tyre column of the identified ϑ."""
    solution: ExactSolution
    """The exact, certified solution at that ϑ."""
    iterations: int
    """Iterations of the joint search (the final exact solve not counted)."""


class _JointProblem:
    """GF over (θ, log τ) in scaled columns: the fixed columns, the offset and the tyre column per τ."""

    def __init__(self, system: LinearResiduals) -> None:
        self.system = system
        e, n, p = system.matrix.shape
        self.equations = e
        self.column = system.parameter_names.index(TYRE_DAMPING)
        self.others = np.array([j for j in range(p) if j != self.column])
        fixed = system.matrix[:, :, self.others].reshape(e * n, -1)  # equation-major rows
        self.scale = np.linalg.norm(fixed, axis=0)
        self.scale[self.scale == 0] = 1.0
        self.fixed = fixed / self.scale
        self.offset = system.offset.reshape(e * n)
        self.dt = system.filters.sample_time_s

    def tyre_column(self, log_tau: float) -> np.ndarray:
        theta = coefficient_from_relaxation_time(float(np.exp(log_tau)), self.dt)
        column = np.zeros((self.equations, self.system.sample_index.size))
        for rate, equation in zip(self.system.tyre_rates_m_s, self.system.tyre_equations, strict=True):
            column[equation] = maxwell_regressor(rate, theta)[self.system.sample_index]
        return column.reshape(-1)

    def residual_norms(self, z: np.ndarray, column: np.ndarray) -> np.ndarray:
        """||r_i|| per sample; z: scaled fixed unknowns, then the tyre damping (its column unscaled)."""
        r = self.fixed @ z[:-1] + column * z[-1] + self.offset
        return np.sqrt(np.square(r.reshape(self.equations, -1)).sum(axis=0))

    def theta(self, z: np.ndarray) -> np.ndarray:
        """The system's θ from the scaled unknowns."""
        theta = np.empty(self.others.size + 1)
        theta[self.others] = z[:-1] / self.scale
        theta[self.column] = z[-1]
        return theta


class _WeightedStep:
    """The majoriser of one iteration: weighted least squares over the fixed columns (factored once) and
    the tyre column of a trial τ, by block elimination (Schur complement on the tyre column)."""

    def __init__(self, problem: _JointProblem, weights: np.ndarray) -> None:
        self.problem = problem
        self.root_w = np.tile(np.sqrt(weights), problem.equations)
        self.weighted_fixed = problem.fixed * self.root_w[:, None]
        self.weighted_offset = self.root_w * problem.offset
        gram = self.weighted_fixed.T @ self.weighted_fixed
        self.factor = cholesky_factor(gram)
        self.cross = self.weighted_fixed.T @ self.weighted_offset
        self.fixed_solution = cholesky_solve(self.factor, self.cross)
        offset_square = float(self.weighted_offset @ self.weighted_offset)
        self.base_value = offset_square - float(self.cross @ self.fixed_solution)
        self.solutions: dict[float, np.ndarray] = {}

    def __call__(self, log_tau: float) -> float:
        """min over z of Σ w·(A z + c)² with the tyre column of τ = exp(log_tau); remembers the z."""
        column = self.problem.tyre_column(log_tau)
        wc = self.root_w * column
        norm = float(np.linalg.norm(wc)) or 1.0
        wc /= norm
        coupling = self.weighted_fixed.T @ wc
        through = cholesky_solve(self.factor, coupling)
        schur = float(wc @ wc - coupling @ through)
        projected = float(wc @ self.weighted_offset - coupling @ self.fixed_solution)
        tyre = -projected / schur if schur > 0 else 0.0
        z = np.append(-self.fixed_solution - through * tyre, tyre / norm)
        self.solutions[log_tau] = z
        return self.base_value + projected * tyre  # = base − projected²/schur


def _local_step(step: _WeightedStep, log_tau: float, width: float, bounds: tuple[float, float]) -> float:
    """Where a parabola through the majoriser at log_tau and ± width puts its minimum (clipped to ±4 widths
    and the bounds); returns the best log τ evaluated, log_tau itself included."""
    low, high = max(bounds[0], log_tau - width), min(bounds[1], log_tau + width)
    points = {x: step(x) for x in {low, log_tau, high}}
    if len(points) == 3:
        (x0, f0), (x1, f1), (x2, f2) = sorted(points.items())
        curvature = (f2 - f1) / (x2 - x1) - (f1 - f0) / (x1 - x0)
        if curvature > 0:
            slope_mid = ((f1 - f0) / (x1 - x0) * (x2 - x1) + (f2 - f1) / (x2 - x1) * (x1 - x0)) / (x2 - x0)
            vertex = x1 - slope_mid * (x2 - x0) / (2.0 * curvature)
            vertex = float(np.clip(vertex, max(bounds[0], x1 - 4 * width), min(bounds[1], x1 + 4 * width)))
            points[vertex] = step(vertex)
    return min(points, key=points.__getitem__)


def fit_relaxation_time(
    system: LinearResiduals,
    bounds_s: tuple[float, float] = RELAXATION_TIME_BOUNDS_S,
    tolerance: float = 1e-8,
    max_iterations: int = 300,
) -> RelaxationFit:
    """Minimise GF over the convex unknowns and the Maxwell relaxation time τ within bounds_s (module
    docstring); the system's current ϑ is the starting point."""
    problem = _JointProblem(system)
    bounds = float(np.log(bounds_s[0])), float(np.log(bounds_s[1]))
    start = relaxation_time_from_coefficient(float(system.tyre_theta), problem.dt)
    log_tau = float(np.clip(np.log(start), *bounds))
    weights = np.ones(problem.fixed.shape[0] // problem.equations)
    objective = np.inf
    iterations, width = 0, LOCAL_WIDTH
    z = np.zeros(problem.others.size + 1)
    for iterations in range(1, max_iterations + 1):
        step = _WeightedStep(problem, weights)
        before = log_tau
        if iterations == 1:  # the whole range once: Brent, the current τ kept if it is better
            current = step(log_tau)
            from scipy.optimize import minimize_scalar  # here: identify with ϑ known never imports it

            found = minimize_scalar(step, bounds=bounds, method="bounded", options={"xatol": FIRST_TOLERANCE})
            log_tau = float(found.x) if found.fun < current else log_tau
        else:
            log_tau = _local_step(step, log_tau, width, bounds)
        width = float(np.clip(abs(log_tau - before), MIN_WIDTH, LOCAL_WIDTH))
        z = step.solutions[log_tau]
        norms = problem.residual_norms(z, problem.tyre_column(log_tau))
        previous, objective = objective, float(norms.sum())
        if previous - objective <= max(tolerance, NEWTON_HANDOVER) * objective:
            break
        floor = 1e-9 * max(float(median(norms)), 1e-300)
        weights = 1.0 / np.maximum(norms, floor)
    tau = float(np.exp(log_tau))
    theta = problem.theta(z)
    if tolerance < NEWTON_HANDOVER:
        at_tau = system.with_tyre_theta(coefficient_from_relaxation_time(tau, problem.dt))
        polished = newton_refit(at_tau, theta, bounds_s, tolerance=min(tolerance, 1e-10))
        if polished.relaxation_time_s is not None and polished.objective < objective:
            tau, theta = polished.relaxation_time_s, polished.theta
    best = system.with_tyre_theta(coefficient_from_relaxation_time(tau, problem.dt))
    return RelaxationFit(tau, best, solve_exact(best, initial=theta), iterations)
