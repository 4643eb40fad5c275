"""The statistical tests of diagnose.py, one object each (tests/estimator/test_doctor_criteria.py).

- EquationTest: is a family's contribution to the equations of motion zero? A Wald test with the sandwich
  covariance of the paper's objective (a block long-run variance of the score, estimator.uncertainty), so a
  residual coloured by the laser's filters and by what the model still lacks is not counted as independent.
- SimulationTest: does the family shrink the free simulation's gap more than chance? A likelihood ratio, the
  output error's samples counted as its effective number of independent ones.
- ScaleSearch: the Wald test of a family whose scale was searched (a friction form's v_s or z): Davies' bound.
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

from estimator.distributions import chi_square_survival, log_davies_bound, student_upper_tail
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
        return self.tests(system, solution, [index], sample_time_s)[0]

    def tests(
        self, system, solution: np.ndarray, sets: list[list[int]], sample_time_s: float
    ) -> list[TestResult]:
        """Each set of unknowns tested, from one covariance at `solution` (none if all sets are empty)."""
        covariance = confidence_intervals(system, solution, sample_time_s).covariance if any(sets) else None
        return [_wald(solution[s], covariance[np.ix_(s, s)]) if s else TestResult(0.0, 0, 1.0) for s in sets]


def _wald(vector: np.ndarray, covariance: np.ndarray) -> TestResult:
    statistic = float(vector @ np.linalg.lstsq(covariance, vector, rcond=None)[0])
    p_value = chi_square_survival(statistic, vector.size) if np.isfinite(statistic) else 1.0
    return TestResult(statistic, vector.size, p_value)


@dataclass(frozen=True)
class ScaleSearch:
    """A Wald test whose family has a scale searched for (low_speed_friction's v_s or z: only under the
    alternative): the largest W is not χ²(q); Davies' (1987) bound P(χ²(q) > W) + V·W^((q−1)/2)·e^(−W/2) /
    (2^(q/2)·Γ(q/2)) gives its p, V the total variation of √W along the search's grid (V = 0: plain χ²)."""

    variation: float = 0.0

    def log_p(self, statistic: float, unknowns: int) -> float:
        """ln of the bound (at most 0)."""
        return log_davies_bound(statistic, unknowns, self.variation)


@dataclass(frozen=True)
class SimulationTest:
    """Likelihood ratio of free simulations with and without a family: n_eff·ln(gap_without²/gap_with²)."""

    def test(self, samples: float, gap_without_m: float, gap_with_m: float, unknowns: int) -> TestResult:
        """samples: the effective number of independent samples of the residual without the family
        (estimator.autocorrelation.effective_samples, summed over its channels)."""
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


@dataclass(frozen=True)
class EachMember:
    """Families named together (catalog.LOAD_PATH) must each be significant given the others (the Wald test of
    its unknowns in their joint fit, at α): else their joint test would carry one on the others' evidence."""

    alpha: float = ALPHA

    def redundant(
        self, system, solution: np.ndarray, members: dict[str, list[int]], sample_time_s: float
    ) -> str | None:
        """Why a member is not significant given the others (None: each is); members: name -> its unknowns'
        indices in `system` (an estimator.equations.LinearResiduals solved by `solution`)."""
        tests = EquationTest().tests(system, solution, list(members.values()), sample_time_s)
        for name, test in zip(members, tests, strict=True):
            if test.p_value > self.alpha:
                w, q, p = test.statistic, test.unknowns, test.p_value
                return f"{name} adds nothing given the others (W = {w:.1f} on {q} unknowns, p = {p:.2g})"
        return None


def intersection_union(*results: TestResult) -> float:
    """The p-value of "every test rejects": the largest of theirs."""
    return max(r.p_value for r in results)


@dataclass(frozen=True)
class Selection:
    """Bonferroni over m candidates (tuples of families): the smallest p (logarithms) wins if at most α/m.
    Nested models, the smaller first: families together wait while one alone is significant; where they beat
    the winner (not theirs) on p and on likelihood (the smaller free-simulation gap: models not nested), their
    most significant member is named instead (a sensor family does not take a round rates in series won)."""

    alpha: float = ALPHA

    def bound(self, tested: int) -> float:  # α/m: the level each of a round's m candidates is held to
        return self.alpha / max(tested, 1)

    def waiting(self, log_p: dict[tuple, float], tested: int) -> list[tuple]:  # the smaller first
        bound = math.log(self.bound(tested))
        return [c for c in log_p if len(c) > 1 and any(log_p.get((m,), 0.0) <= bound for m in c)]

    def choose(self, log_p: dict[tuple, float], tested: int, gap_m: dict | None = None) -> tuple | None:
        waiting, gap, rank = self.waiting(log_p, tested), gap_m or {}, lambda k: (log_p[k], str(k))
        best = min((c for c in log_p if c not in waiting), key=rank, default=None)
        for c in sorted(waiting, key=rank):  # (best is one of their members at the least)
            if rank(c) < rank(best) and best[0] not in c and gap.get(c, math.inf) < gap.get(best, math.inf):
                best = min(((m,) for m in c if (m,) in log_p), key=rank)
        return best if best is not None and log_p[best] <= math.log(self.bound(tested)) else None


@dataclass(frozen=True)
class GoodnessOfFit:
    """The final model's gap against its bootstrap draws' (the equation objective is not tested: its null
    depends on the noise inside the excitation band, not measurable apart from the response)."""

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
