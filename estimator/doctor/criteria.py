"""The doctor's statistical tests, each an object with one job and its own test
(tests/estimator/test_doctor_criteria.py). The procedure that uses them is estimator.doctor.diagnose.

- EquationTest: is a family's contribution to the equations of motion zero? A Wald test with the sandwich
  covariance of the paper's objective (a block long-run variance of the score, estimator.uncertainty), so a
  residual coloured by the laser's filters and by what the model still lacks is not counted as independent
  samples.
- SimulationTest: does the family shrink the free simulation's gap more than chance? A likelihood ratio on
  the output-error residual, whose samples are counted as the residual's effective number of independent
  samples (its autocorrelation: estimator.doctor.residuals.effective_samples).
- A family is *significant* when both are (an intersection-union test: its size is at most the larger of
  the two tests' sizes, so no correction is owed for asking both). The equations alone over-detect where the
  model's own approximation (a piecewise-linear damper curve for a smooth one) correlates with a family's
  columns; the simulation alone is blind to a family that the curve or the masses can stand in for.
- Selection: of the m candidates of a round, the one with the smallest p-value is named when p ≤ α/m
  (Bonferroni: the chance of naming anything in a round where nothing is missing is at most α).
- GoodnessOfFit: does what the final model leaves look like what it would leave if it were the truth? A
  parametric bootstrap: the final model's structure is re-identified on `draws` synthetic recordings of the
  response of a plausible truth (the structure at twice the curve's resolution, with a damper whose force
  rises with velocity: estimator.doctor.expected) read with noise drawn as the recording's own (level,
  colour, reading resolution), and simulated again; the observed gap is compared with those draws (a
  Student's t prediction interval of its logarithm), the equation objective's ratio reported beside it.

The doctor's decision constants are ALPHA and the bases' sizes (estimator.doctor.catalog: HINGE_FRACTIONS,
STRIBECK_VELOCITIES_M_S) and the bootstrap's size (DiagnoseOptions.draws).
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
    """Wald test of some of θ's unknowns (and of appended parameter columns) against zero:
    W = θ_fᵀ V_ff⁻¹ θ_f ~ χ²(q) when they are zero."""

    def test(
        self,
        system,
        theta: np.ndarray,
        names: list[str],
        sample_time_s: float,
        extra_values: np.ndarray | None = None,
    ) -> TestResult:
        """system, theta: the fitted model with the family (estimator.equations.LinearResiduals); names: the
        family's unknowns in θ; extra_values: values of parameters whose columns were appended to `system`
        after θ's (channel parameters: their columns are the residual's derivatives, so that at the fitted
        θ their own estimate is zero and the test is of `extra_values`)."""
        index = [system.parameter_names.index(n) for n in names]
        values = [float(theta[k]) for k in index]
        full_theta = theta
        if extra_values is not None and extra_values.size:
            first = len(theta)
            index += list(range(first, first + extra_values.size))
            values += [float(v) for v in extra_values]
            full_theta = np.concatenate([theta, np.zeros(extra_values.size)])
        if not index:
            return TestResult(0.0, 0, 1.0)
        covariance = confidence_intervals(system, full_theta, sample_time_s).covariance
        block = covariance[np.ix_(index, index)]
        vector = np.array(values)
        statistic = float(vector @ np.linalg.lstsq(block, vector, rcond=None)[0])
        if not np.isfinite(statistic):
            return TestResult(statistic, len(index), 1.0)
        return TestResult(statistic, len(index), chi_square_survival(statistic, len(index)))

    def test_at(self, system, solution: np.ndarray, index: list[int], sample_time_s: float) -> TestResult:
        """Wald test of solution[index] against zero, the covariance at `solution` (every unknown of the
        system, appended columns included)."""
        if not index:
            return TestResult(0.0, 0, 1.0)
        covariance = confidence_intervals(system, solution, sample_time_s).covariance
        block = covariance[np.ix_(index, index)]
        vector = solution[index]
        statistic = float(vector @ np.linalg.lstsq(block, vector, rcond=None)[0])
        if not np.isfinite(statistic):
            return TestResult(statistic, len(index), 1.0)
        return TestResult(statistic, len(index), chi_square_survival(statistic, len(index)))


@dataclass(frozen=True)
class SimulationTest:
    """Likelihood ratio of the free simulation with and without the family: n_eff·ln(gap_without² /
    gap_with²) ~ χ²(q), n_eff the effective number of independent samples of the residual without."""

    def test(self, samples: float, gap_without_m: float, gap_with_m: float, unknowns: int) -> TestResult:
        """samples: the effective number of independent samples of the residual without the family
        (estimator.doctor.residuals.effective_samples, summed over its channels)."""
        q = max(unknowns, 1)
        if not np.isfinite(gap_with_m) and not np.isfinite(gap_without_m):
            # neither model can be simulated: the simulation cannot tell them apart and says nothing
            # against the family (statistic nan, p = 1 would veto every family): the equations decide
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
    """Bonferroni over a round's candidates: the smallest p-value wins if it is at most α/m. The p-values
    are given as logarithms (residuals.log_chi_square_survival): large effects have p-values that would
    underflow to 0 together, and which of them is the most significant must still be decided."""

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
    """The final model's gap against `draws` bootstrap draws of the same (module docstring): p from a normal
    prediction interval of the gap's logarithm (the draws' mean and standard deviation, widened by
    √(1 + 1/draws) for their own uncertainty). The equation objective is reported beside it (its ratio to
    the draws'), not tested: its null depends on the noise's spectrum inside the excitation band, which
    cannot be measured apart from the vehicle's response (measured on DEV clean draws of the foreign world:
    1.2-1.5 times the draws' with the gap at 0.4-1.0 times theirs)."""

    alpha: float = ALPHA

    def p_value(self, gap_m: float, draw_gaps_m: list[float]) -> float:
        """p of a gap at least this large if the final model were the truth: Student's t prediction
        interval of the gap's logarithm from the draws' (n − 1 degrees of freedom: their mean and spread
        are estimated from a few draws). A model that diverges has 0; so has one whose own
        re-identifications diverge (fewer than two finite draws: nothing shows it could be the truth)."""
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
