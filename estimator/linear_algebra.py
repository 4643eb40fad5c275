"""Small dense linear algebra in numpy alone: Cholesky solves of symmetric positive definite systems, and a
stack of small non-negative least-squares fits (small_nnls: the doctor's noise law).

Why not scipy.linalg.cho_factor/cho_solve: importing scipy.linalg costs about 0.25 s (scipy's array-API
layer clones numpy's namespace, importing numpy.f2py, numpy.testing and numpy.ma) and `shockbench
identify` is a fresh process each time; the systems solved here have tens of unknowns, where the two
triangular solves by numpy.linalg.solve cost microseconds. A matrix that is not positive definite raises
numpy.linalg.LinAlgError, as scipy's does (the callers fall back to a least-squares solve).
"""

from __future__ import annotations

import numpy as np


def cholesky_factor(matrix: np.ndarray) -> np.ndarray:
    """The lower Cholesky factor L of a symmetric positive definite matrix (L Lᵀ = matrix)."""
    return np.linalg.cholesky(matrix)


def cholesky_solve(lower: np.ndarray, right: np.ndarray) -> np.ndarray:
    """x with L Lᵀ x = right, from the lower factor L: forward then backward triangular solve."""
    return np.linalg.solve(lower.T, np.linalg.solve(lower, right))


def small_nnls(designs: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per design of a stack (count, rows, a few columns): x ≥ 0 minimising ||design·x − target||, and that
    norm: least squares on every set of free columns (the rest at zero; normal equations of unit columns
    for the whole stack, by pseudo-inverse: ρ = 0 makes the AR(1) column the white one), the fewest and
    earliest columns winning a tie. Not scipy's nnls: its import costs more than the fit, and it would loop
    over the stack; the test checks the two agree."""
    count, _, columns = designs.shape
    scale = np.linalg.norm(designs, axis=1)
    scale[scale == 0.0] = 1.0
    scaled = designs / scale[:, None, :]
    gram, moment = np.einsum("nrk,nrl->nkl", scaled, scaled), np.einsum("nrk,r->nk", scaled, target)
    best_misfit, best = np.full(count, float(np.linalg.norm(target))), np.zeros((count, columns))
    tie = 1e-12 * best_misfit[0]
    subsets = [[k for k in range(columns) if mask >> k & 1] for mask in range(1, 2**columns)]
    for free in sorted(subsets, key=lambda subset: (len(subset), subset)):
        inverse = np.linalg.pinv(gram[:, free][:, :, free], rcond=1e-13, hermitian=True)
        x = np.zeros((count, columns))
        x[:, free] = np.einsum("nkl,nl->nk", inverse, moment[:, free])
        misfit = np.linalg.norm(np.einsum("nrk,nk->nr", scaled, x) - target, axis=1)
        better = np.all(x >= 0.0, axis=1) & (misfit < best_misfit - tie)
        best_misfit, best = np.where(better, misfit, best_misfit), np.where(better[:, None], x, best)
    return best / scale, best_misfit
