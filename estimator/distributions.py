"""Tail probabilities of the χ² and Student's t distributions, and Davies' bound for a searched χ², in
closed forms: the model doctor's tests need them per candidate and per round, and scipy.stats costs a
process about 0.1 s to import (its p-values agree: tests/estimator/test_distributions.py)."""

from __future__ import annotations

import math


def chi_square_survival(statistic: float, degrees: int) -> float:
    """P(χ² > statistic) with `degrees` degrees of freedom (log_chi_square_survival)."""
    return min(1.0, math.exp(log_chi_square_survival(statistic, degrees)))


def log_chi_square_survival(statistic: float, degrees: int) -> float:
    """ln P(χ² > s), d = `degrees` (scipy.special.chdtrc's tail without its 0.1 s import), in logarithms
    so that p-values that underflow to 0 still compare. Even d: e^(−s/2)·Σ_{k<d/2} (s/2)^k / k!; odd d:
    erfc(√(s/2)) + e^(−s/2)·Σ_{k=1}^{(d−1)/2} (s/2)^(k−1/2) / Γ(k + 1/2), erfc(x) ≈ e^(−x²)/(x√π) above 25."""
    if degrees <= 0:
        raise ValueError(f"chi_square_survival takes a positive number of degrees, not {degrees}")
    if statistic <= 0:
        return 0.0
    if not math.isfinite(statistic):
        return -math.inf
    half = statistic / 2.0
    if half == 0.0:  # a statistic so small that half of it underflows: P = 1
        return 0.0
    log_half = math.log(half)
    if degrees % 2 == 0:
        terms = [k * log_half - half - math.lgamma(k + 1) for k in range(degrees // 2)]
    else:
        root = math.sqrt(half)
        tail = math.log(math.erfc(root)) if root < 25.0 else -half - math.log(root * math.sqrt(math.pi))
        terms = [tail] + [
            (k - 0.5) * log_half - half - math.lgamma(k + 0.5) for k in range(1, (degrees + 1) // 2)
        ]
    top = max(terms)
    return min(0.0, top + math.log(sum(math.exp(t - top) for t in terms)))


def log_davies_bound(statistic: float, degrees: int, variation: float) -> float:
    """ln of Davies' (1987) upper bound on P(max W > s) for a χ²(d) process W along a searched parameter
    (one that exists only under the alternative, so that the largest W is not χ²(d)):
    P(χ²(d) > s) + V·s^((d−1)/2)·e^(−s/2) / (2^(d/2)·Γ(d/2)), V the total variation of √W along the search.
    V = 0 is the χ² tail."""
    pointwise = log_chi_square_survival(statistic, degrees)
    if variation <= 0.0 or statistic <= 0.0 or not math.isfinite(statistic):
        return pointwise
    half = 0.5 * degrees
    crossings = (
        math.log(variation)
        + (half - 0.5) * math.log(statistic)
        - 0.5 * statistic
        - half * math.log(2.0)
        - math.lgamma(half)
    )
    top, low = max(pointwise, crossings), min(pointwise, crossings)
    return min(0.0, top + math.log1p(math.exp(low - top)))  # ln(e^pointwise + e^crossings)


def student_upper_tail(t: float, degrees: int) -> float:
    """P(T > t) for Student's t with a whole number of degrees of freedom (the closed forms of Abramowitz
    and Stegun 26.7.3-4: a finite sum in cos θ, θ = atan(t/√ν)), without importing scipy.stats."""
    theta = math.atan2(t, math.sqrt(degrees))
    c2, s = math.cos(theta) ** 2, math.sin(theta)
    if degrees % 2 == 1:
        term, total = math.cos(theta), 0.0
        for k in range(1, (degrees - 1) // 2 + 1):
            total += term
            term *= c2 * (2 * k) / (2 * k + 1)
        central = (2.0 / math.pi) * (theta + s * total) if degrees > 1 else (2.0 / math.pi) * theta
    else:
        term, total = 1.0, 0.0
        for k in range(degrees // 2):
            total += term
            term *= c2 * (2 * k + 1) / (2 * k + 2)
        central = s * total
    return 0.5 * (1.0 - central)
