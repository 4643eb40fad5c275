"""Fit the paper's hyperbolic-tangent damper model (eq 10) to identified curve points, robustly, and flag the
points that do not belong (the paper's Table 2 has one: 10 821.8 N where about 1 082 N fits).

For fixed μ and β the model is linear in c_s and κ, so a grid over (μ, β) with robust (Tukey-reweighted)
linear fits, ranked by least-trimmed squares, finds the basin without being pulled by an outlier; a
bounded Levenberg-Marquardt with a Cauchy loss (by reweighting) then refines all four parameters. The loss
scale is the residual spread estimated robustly (MAD). A point is an outlier when its residual exceeds
OUTLIER_SIGMAS robust standard deviations and also OUTLIER_FLOOR_FRACTION of the peak force: only gross
errors are flagged, not a real damper's knee that the tanh form cannot follow.

The reported parameters are then a least-squares fit to all inliers, each point weighted by the velocity
interval it stands for (half the distance to each neighbour: the trapezoid rule), so the cost is the
squared distance between the curves over the velocity range rather than a count over knots; on a uniform
grid it only halves the two end points, which stand for half an interval each. c_s and κ are kept ≥ 0:
eq 10's knee adds force (κ > 0) on a linear part that rises (c_s > 0), and a κ < 0 "fit" is a different
curve family. Both matter on the paper's own data: Table 3 from Table 2 comes within 8.8, 14.1 and 11.7 N
of the paper's curves (Maxwell, Kelvin-Voigt, constant stiffness), 8.5, 19.0 and 40.8 N with equal
weights and free signs (tests/estimator/test_paper_table3.py).

Why not scipy.optimize.least_squares: importing scipy.optimize costs about 0.3 s more than identify's other
imports (linprog, shgo and their dependencies, the docstrings of some hundred functions rewritten), a
quarter of a whole `shockbench identify`, which runs this fit on a handful of points. Four unknowns with
an analytic Jacobian need no more than the damped Gauss-Newton step below; it stops at a relative cost
change below 1e-15, tighter than scipy's default 1e-8, so it lands on the same minimum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.damper import TanhCurve
from estimator.order_statistics import median

OUTLIER_SIGMAS = 5.0
OUTLIER_FLOOR_FRACTION = 0.2
"""A flagged point is off the robust fit by more than this share of the peak force. At 0.15 the last point
of the paper's Table 2 Kelvin-Voigt column (1217.4 N, 234 N = 19% above the robust fit of the rest, a real
upturn that the tanh form cannot follow) was flagged, and the fit of the other 19 then missed all 20 by
59 N RMS against 33 N with it (tests/estimator/test_paper_table3.py)."""
MAD_TO_SIGMA = 1.4826
MU_SPAN_RANGE = (0.2, 40.0)
"""μ·max|v| searched: from a nearly linear damper to a sharp valve knee."""
TRIM_KEEP = 0.8
"""Share of points whose squared residuals make the trimmed cost (robust to up to 20% outliers)."""
TUKEY_C = 4.685
BETA_LIMIT = 4.0
"""|β| beyond this makes tanh an exponential that can chase an outlier instead of describing a damper."""


@dataclass(frozen=True)
class TanhFit:
    curve: TanhCurve
    rms_N: float
    """RMS residual over the inlier points."""
    outliers: list[int]
    """0-based indices of the points flagged as outliers."""

    def as_dict(self) -> dict[str, object]:
        return {**self.curve.as_dict(), "rms_N": self.rms_N, "outliers": self.outliers}


def _robust_sigma(residual: np.ndarray) -> float:
    return float(MAD_TO_SIGMA * median(np.abs(residual - median(residual))))


def _model(params: np.ndarray, v: np.ndarray) -> np.ndarray:
    c_s, kappa, mu, beta = params
    return c_s * v + kappa * (np.tanh(mu * v + beta) - np.tanh(beta))


def _jacobian(params: np.ndarray, v: np.ndarray) -> np.ndarray:
    """∂ model / ∂ (c_s, κ, μ, β) at every point, (n, 4)."""
    _, kappa, mu, beta = params
    inner = np.tanh(mu * v + beta)
    slope = 1.0 - inner**2  # sech²(μ·v + β)
    at_zero = 1.0 - np.tanh(beta) ** 2
    return np.column_stack([v, inner - np.tanh(beta), kappa * v * slope, kappa * (slope - at_zero)])


REFINE_ITERATIONS = 500
COST_TOLERANCE = 1e-15


def _refine(
    v: np.ndarray,
    f: np.ndarray,
    start: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    loss_scale_N: float | None,
    point_weight: np.ndarray | None = None,
) -> np.ndarray:
    """Parameters minimising Σ w·ρ(residual) within the bounds, from `start`: ρ(r) = r² (loss_scale_N None)
    or the Cauchy loss s²·ln(1 + (r/s)²); w is `point_weight` (1 for every point when None).
    Levenberg-Marquardt on the reweighted normal equations (w times the Cauchy weight 1/(1 + (r/s)²) per
    point), Marquardt's diagonal scaling (the step is invariant to the
    parameters' units, like scipy's x_scale="jac"), each step clipped to the bounds and kept only if it
    lowers the cost."""

    point_weight = np.ones_like(v) if point_weight is None else point_weight

    def cost(params: np.ndarray) -> float:
        residual = _model(params, v) - f
        if loss_scale_N is None:
            return float(point_weight @ residual**2)
        return float(loss_scale_N**2 * (point_weight @ np.log1p((residual / loss_scale_N) ** 2)))

    params = np.clip(start, lower, upper)
    current = cost(params)
    damping = 1e-3
    for _ in range(REFINE_ITERATIONS):
        residual = _model(params, v) - f
        jacobian = _jacobian(params, v)
        weights = point_weight
        if loss_scale_N is not None:
            weights = weights / (1.0 + (residual / loss_scale_N) ** 2)
        normal = jacobian.T @ (jacobian * weights[:, None])
        gradient = jacobian.T @ (weights * residual)
        diagonal = np.maximum(np.diag(normal), 1e-12 * max(float(np.max(np.diag(normal))), 1e-300))
        # a parameter on its bound that the cost would push past it is held there (active set): a clipped
        # step would otherwise stall on the bound
        held = ((params <= lower) & (gradient > 0)) | ((params >= upper) & (gradient < 0))
        free = np.flatnonzero(~held)
        while damping < 1e16:
            step = np.zeros_like(params)
            try:
                step[free] = np.linalg.solve(
                    normal[np.ix_(free, free)] + damping * np.diag(diagonal[free]), -gradient[free]
                )
            except np.linalg.LinAlgError:
                damping *= 10.0
                continue
            trial = np.clip(params + step, lower, upper)
            trial_cost = cost(trial)
            if trial_cost <= current:
                break
            damping *= 10.0
        else:
            return params
        improvement = current - trial_cost
        params, current = trial, trial_cost
        damping = max(damping / 10.0, 1e-12)
        if improvement <= COST_TOLERANCE * max(current, 1e-300):
            return params
    return params


def _trimmed_cost(residual: np.ndarray) -> float:
    """Least-trimmed squares: the sum of the smallest TRIM_KEEP share of squared residuals."""
    r2 = np.sort(residual**2)
    return float(np.sum(r2[: max(3, int(TRIM_KEEP * r2.size))]))


def _non_negative_pairs(gram: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """(c_s, κ) ≥ 0 minimising cᵀ·G·c − 2·cᵀ·b for each of K 2×2 systems (gram (K, 2, 2), rhs (K, 2)):
    the unconstrained solution where it is non-negative, else the better of the two one-sided ones."""
    coef = np.linalg.solve(gram, rhs[:, :, None])[:, :, 0]
    infeasible = np.any(coef < 0.0, axis=1)
    if np.any(infeasible):
        g, b = gram[infeasible], rhs[infeasible]
        only_c = np.column_stack([np.maximum(b[:, 0] / g[:, 0, 0], 0.0), np.zeros(len(b))])
        only_k = np.column_stack([np.zeros(len(b)), np.maximum(b[:, 1] / g[:, 1, 1], 0.0)])

        def objective(c: np.ndarray) -> np.ndarray:
            return np.einsum("ki,kij,kj->k", c, g, c) - 2.0 * np.einsum("ki,ki->k", c, b)

        coef[infeasible] = np.where((objective(only_c) <= objective(only_k))[:, None], only_c, only_k)
    return coef


def _linear_fits(
    v: np.ndarray,
    f: np.ndarray,
    mu: np.ndarray,
    beta: np.ndarray,
    point_weight: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Best (c_s, κ) ≥ 0 for each of K fixed (μ, β) pairs at once (batched 2×2 normal equations). Without
    `point_weight`: Tukey-bisquare reweighted, ranked by the trimmed cost; with it: weighted least squares,
    ranked by the weighted sum of squares. Returns params (K, 4) and the cost of each (K,)."""
    basis = np.stack(
        [
            np.broadcast_to(v, (mu.size, v.size)),
            np.tanh(mu[:, None] * v + beta[:, None]) - np.tanh(beta)[:, None],
        ],
        axis=2,
    )  # (K, n, 2)
    robust = point_weight is None
    weights = np.ones((mu.size, v.size)) if robust else np.broadcast_to(point_weight, (mu.size, v.size))
    floor = 1e-9 * (np.max(np.abs(f)) + 1.0)
    ridge = 1e-12 * np.eye(2)
    for _ in range(6 if robust else 1):
        weighted = basis * weights[:, :, None]
        gram = np.einsum("kni,knj->kij", weighted, basis) + ridge
        coef = _non_negative_pairs(gram, np.einsum("kni,n->ki", weighted, f))
        r = f - np.einsum("kni,ki->kn", basis, coef)
        if robust:
            centred = r - median(r, axis=1, keepdims=True)
            sigma = np.maximum(MAD_TO_SIGMA * median(np.abs(centred), axis=1, keepdims=True), floor)
            u = r / (TUKEY_C * sigma)
            weights = np.clip(1.0 - u**2, 0.0, None) ** 2 + 1e-6
    if robust:
        r2 = np.sort(r**2, axis=1)
        cost = r2[:, : max(3, int(TRIM_KEEP * v.size))].sum(axis=1)
    else:
        cost = np.einsum("kn,n->k", r**2, point_weight)
    return np.column_stack([coef, mu, beta]), cost


def _interval_weights(v: np.ndarray) -> np.ndarray:
    """Each point's share of the velocity range: half the distance to each neighbour in velocity order (the
    trapezoid rule), scaled to sum to the number of points."""
    order = np.argsort(v, kind="stable")
    ordered = v[order]
    edges = np.concatenate([ordered[:1], (ordered[1:] + ordered[:-1]) / 2.0, ordered[-1:]])
    weight = np.empty_like(v)
    weight[order] = np.diff(edges)
    return weight * (v.size / np.sum(weight))


MIN_POINTS = 5
"""The fewest curve points a tanh fit takes (four parameters, and one more to judge the fit)."""


def fit_tanh(velocity_m_s: np.ndarray, force_N: np.ndarray) -> TanhFit:
    """Robust fit of f = c_s·v + κ·(tanh(μ·v + β) − tanh(β)) to curve points; needs at least 5 points."""
    v = np.asarray(velocity_m_s, dtype=float)
    f = np.asarray(force_N, dtype=float)
    if v.shape != f.shape or v.ndim != 1:
        raise ValueError("velocity and force must be 1-D arrays of the same length")
    if v.size < MIN_POINTS:
        raise ValueError(f"a tanh fit needs at least {MIN_POINTS} points, got {v.size}")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(f))):
        raise ValueError("curve points must be finite numbers")
    span = float(np.max(np.abs(v)))
    if span == 0:
        raise ValueError("all velocities are zero")
    mu_grid, beta_grid = np.meshgrid(
        np.geomspace(MU_SPAN_RANGE[0], MU_SPAN_RANGE[1], 16) / span,
        np.linspace(-BETA_LIMIT + 1, BETA_LIMIT - 1, 15),
    )
    mu_grid, beta_grid = mu_grid.ravel(), beta_grid.ravel()
    candidates, costs = _linear_fits(v, f, mu_grid, beta_grid)
    best_params = candidates[int(np.argmin(costs))]
    residual = f - _model(best_params, v)
    scale = max(_robust_sigma(residual), 1e-6 * (np.max(np.abs(f)) + 1.0))
    lower = [0.0, 0.0, MU_SPAN_RANGE[0] / 2 / span, -BETA_LIMIT]
    upper = [np.inf, np.inf, MU_SPAN_RANGE[1] * 2 / span, BETA_LIMIT]
    lower, upper = np.array(lower), np.array(upper)
    refined = _refine(v, f, best_params, lower, upper, scale)

    def robust_cost(p: np.ndarray) -> float:
        return _trimmed_cost(f - _model(p, v))

    params = refined if robust_cost(refined) <= robust_cost(best_params) else best_params
    residual = f - _model(params, v)
    sigma = max(_robust_sigma(residual), 1e-12)
    floor = OUTLIER_FLOOR_FRACTION * float(np.max(np.abs(f)))
    flagged = np.abs(residual) > np.maximum(OUTLIER_SIGMAS * sigma, floor)
    # final parameters: least squares on the inliers weighted by their velocity intervals, so a curve that is
    # not of the tanh form is described as a whole over its velocity range rather than by its best-fitting
    # 80%; started from the robust fit and from the best of the grid under this cost, the lower one kept
    keep = ~flagged
    weight = _interval_weights(v[keep])
    grid, grid_costs = _linear_fits(v[keep], f[keep], mu_grid, beta_grid, weight)

    def weighted_cost(p: np.ndarray) -> float:
        return float(weight @ (f[keep] - _model(p, v[keep])) ** 2)

    params = min(
        (
            _refine(v[keep], f[keep], start, lower, upper, None, weight)
            for start in (params, grid[np.argmin(grid_costs)])
        ),
        key=weighted_cost,
    )
    inliers = (f - _model(params, v))[keep]
    rms = float(np.sqrt(np.mean(inliers**2))) if inliers.size else float("nan")
    curve = TanhCurve(*map(float, params))
    return TanhFit(curve, rms, [int(i) for i in np.nonzero(flagged)[0]])
