"""The score test of columns added to a fitted system of the paper's objective (estimator.newton_refit's
GF = Σᵢ ||rᵢ||): how much they would lower it, by one Newton step from the optimum, without solving the
extended system; and the profile of that statistic along a scale the columns have, searched (a parameter
that exists only with them). The model doctor profiles a friction form's scale so (estimator.doctor.fitting).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.equations import LinearResiduals
from estimator.newton_refit import hessian_factors


class AddedColumnsScore:
    """At a system's optimum θ, the score test of columns that could be added to it, many sets cheaply: the
    gradient g = Σ Cᵢᵀuᵢ of the paper's objective along them and the Schur complement S of their block in its
    Hessian (estimator.newton_refit's, the system's own block factored once); statistic gᵀS⁻¹g, twice the
    objective's fall by one Newton step, and that step's values −S⁻¹g."""

    def __init__(self, system: LinearResiduals, theta: np.ndarray) -> None:
        residual = system.residuals(theta)
        self.norms = np.maximum(np.sqrt(np.sum(residual**2, axis=0)), 1e-12)
        self.unit = residual / self.norms
        matrix = np.moveaxis(system.matrix, 2, 0)  # (p, e, n)
        self.scale = np.maximum(np.linalg.norm(matrix.reshape(matrix.shape[0], -1), axis=1), 1e-300)
        self.flat, self.along = self._parts(matrix / self.scale[:, None, None])
        bread = self.flat @ self.flat.T - self.along @ self.along.T
        self.inverse = np.linalg.pinv(bread)

    def _parts(self, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return hessian_factors(columns, self.unit, np.sqrt(self.norms))

    def of(self, columns: dict[str, np.ndarray]) -> tuple[float, np.ndarray]:
        added = np.stack(list(columns.values()))
        gradient = np.einsum("qen,en->q", added, self.unit)
        flat, along = self._parts(added)
        cross = flat @ self.flat.T - along @ self.along.T
        schur = flat @ flat.T - along @ along.T - cross @ self.inverse @ cross.T
        step = -np.linalg.lstsq(schur, gradient, rcond=None)[0]
        return float(-gradient @ step), step


SCALE_STEPS_PER_OCTAVE = 4
"""The grid a scale is searched on (numerical: its precision, 19%, and the resolution at which the
statistic's variation along the search is measured, estimator.distributions.log_davies_bound)."""


def log_grid(low: float, high: float) -> np.ndarray:
    """log2 of the scales from `low` to `high`, SCALE_STEPS_PER_OCTAVE a octave (both ends on it)."""
    low_log2, high_log2 = math.log2(low), math.log2(high)
    return np.linspace(low_log2, high_log2, math.ceil((high_log2 - low_log2) * SCALE_STEPS_PER_OCTAVE) + 1)


@dataclass(frozen=True)
class ScoreProfile:
    """The score statistic T(s) of columns with a scale s along a grid (log2 s), and where their one-step
    values are admissible."""

    grid_log2: np.ndarray
    statistic: np.ndarray
    admissible: np.ndarray

    def ranked(self, scales: np.ndarray | float = 1.0) -> tuple[list[int], float]:
        """The admissible grid indices by Z = T / scales, largest first (none admissible: the largest), and
        the total variation of √Z along the grid (Davies' V, estimator.distributions.log_davies_bound)."""
        z = np.maximum(self.statistic / scales, 0.0)
        order = sorted(range(z.size), key=lambda k: (not self.admissible[k], -z[k]))
        variation = float(np.sum(np.abs(np.diff(np.sqrt(z)))))
        return [k for k in order if self.admissible[k]] or order[:1], variation
