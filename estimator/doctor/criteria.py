"""The doctor's statistical tests, one object each (tests/estimator/test_doctor_criteria.py), for the
procedure of estimator.doctor.diagnose.

- EquationTest: is a family's contribution to the equations of motion zero? A Wald test with the sandwich
  covariance of the paper's objective (a block long-run variance of the score, estimator.uncertainty), so a
  residual coloured by the laser's filters and by what the model still lacks is not counted as independent.
- SimulationTest: does the family shrink the free simulation's gap more than chance? A likelihood ratio, the
  output error's samples counted as its effective number of independent ones.
- intersection_union: significant when both are (size at most the larger, no correction owed). The equations
  alone over-detect where the model's own approximation (a piecewise-linear curve for a smooth damper)
  correlates with a family's columns; the simulation alone is blind to what the curve or masses stand in for.
- Selection: Bonferroni over a round's m candidates; GoodnessOfFit: the final model's gap against its
  parametric bootstrap (estimator.doctor.expected).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.doctor.residuals import chi_square_survival
from estimator.uncertainty import confidence_intervals

ALPHA = 0.05
"""Family-wise error rate of a round (naming an effect where none is missing) and false-alarm rate of the
goodness-of-fit test ("unexplained" where nothing is left unexplained)."""


@dataclass(frozen=True)
class TestResult:
    """statistic (Wald W or likelihood ratio), unknowns q (degrees of freedom), p-value."""

    statistic: float
    unknowns: int
    p_value: float


@dataclass(frozen=True)
class EquationTest:
    """Wald test of some unknowns against zero: W = θ_fᵀ V_ff⁻¹ θ_f ~ χ²(q) when they are zero."""

    def test(self, system, solution: np.ndarray, index: list[int], sample_time_s: float) -> TestResult:
        """system: an estimator.equations.LinearResiduals (appended columns included) solved by `solution`;
        the test of solution[index], the covariance at `solution`."""
        if not index:
            return TestResult(0.0, 0, 1.0)
        covariance = confidence_intervals(system, solution, sample_time_s).covariance
        vector = solution[index]
        statistic = float(vector @ np.linalg.lstsq(covariance[np.ix_(index, index)], vector, rcond=None)[0])
        p_value = chi_square_survival(statistic, len(index)) if np.isfinite(statistic) else 1.0
        return TestResult(statistic, len(index), p_value)


@dataclass(frozen=True)
class SimulationTest:
    """Likelihood ratio of the free simulation with and without the family: n_eff·ln(gap_without² /
    gap_with²) ~ χ²(q)."""

    def test(self, samples: float, gap_without_m: float, gap_with_m: float, unknowns: int) -> TestResult:
        """samples: the effective number of independent samples of the residual without the family
        (estimator.doctor.residuals.effective_samples, summed over its channels)."""
        q = max(unknowns, 1)
        if not np.isfinite(gap_with_m) and not np.isfinite(gap_without_m):
            # neither model simulates: no evidence against the family (p = 1 would veto every one)
            return TestResult(math.nan, q, 0.0)
        if not np.isfinite(gap_with_m):
            return TestResult(-np.inf, q, 1.0)
        if not np.isfinite(gap_without_m):
            return TestResult(np.inf, q, 0.0)  # the model without diverges, the model with does not
        statistic = float(samples * math.log(gap_without_m**2 / gap_with_m**2))
        return TestResult(statistic, q, chi_square_survival(statistic, q) if statistic > 0 else 1.0)


def intersection_union(*results: TestResult) -> float:
    """The p-value of "every test rejects": the largest of theirs."""
    return max(r.p_value for r in results)


@dataclass(frozen=True)
class Selection:
    """The smallest p-value of a round wins if at most α/m. Given as logarithms: those of large effects
    underflow to 0 together, and which is the most significant must still be decided."""

    alpha: float = ALPHA

    def choose(self, log_p_values: dict) -> object | None:
        if not log_p_values:
            return None
        best = min(log_p_values, key=lambda k: (log_p_values[k], str(k)))
        return best if log_p_values[best] <= math.log(self.alpha / len(log_p_values)) else None


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


@dataclass(frozen=True)
class GoodnessOfFit:
    """The final model's gap against its bootstrap draws'. The equation objective is reported, not tested:
    its null depends on the noise inside the excitation band, not measurable apart from the response."""

    alpha: float = ALPHA

    def p_value(self, gap_m: float, draw_gaps_m: list[float]) -> float:
        """p of a gap at least this large if the final model were the truth: Student's t prediction interval
        of the gap's logarithm (the draws' mean and spread × √(1 + 1/n), n − 1 degrees of freedom). 0 if the
        model diverges or its re-identifications do (under two finite: nothing shows it could be true)."""
        if not np.isfinite(gap_m):
            return 0.0
        finite = np.log([d for d in draw_gaps_m if np.isfinite(d) and d > 0])
        if finite.size < 2:
            return 0.0
        spread = float(np.std(finite, ddof=1)) * math.sqrt(1.0 + 1.0 / finite.size)
        z = (math.log(gap_m) - float(np.mean(finite))) / max(spread, 1e-12)
        return student_upper_tail(z, finite.size - 1)

    def unexplained(self, p: float) -> bool:
        return p < self.alpha
