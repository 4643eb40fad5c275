"""Cholesky solves of small symmetric positive definite systems in numpy alone.

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
