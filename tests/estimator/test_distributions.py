"""estimator.distributions' closed forms against scipy.stats, over the statistics and degrees of freedom
the model doctor's tests use (χ² with 1-40 degrees, Student's t with 1-20)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from estimator.distributions import chi_square_survival, log_chi_square_survival, student_upper_tail


@pytest.mark.parametrize("degrees", [1, 2, 3, 4, 5, 8, 13, 40])
def test_the_chi_square_tail_is_scipys(degrees: int) -> None:
    for statistic in np.geomspace(1e-3, 400.0, 60):
        expected = float(stats.chi2.logsf(statistic, degrees))
        assert log_chi_square_survival(float(statistic), degrees) == pytest.approx(
            expected, rel=1e-9, abs=1e-12
        )
        assert chi_square_survival(float(statistic), degrees) == pytest.approx(math.exp(expected), rel=1e-9)


@pytest.mark.parametrize("degrees", [1, 2, 3, 4, 7, 20])
def test_the_student_t_upper_tail_is_scipys(degrees: int) -> None:
    for t in np.linspace(-8.0, 8.0, 81):
        assert student_upper_tail(float(t), degrees) == pytest.approx(
            float(stats.t.sf(t, degrees)), rel=1e-9, abs=1e-15
        )
