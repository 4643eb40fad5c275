"""The score test of added columns (estimator.score_test) against the fit it stands for: on a system of the
paper's objective (GF = Σᵢ ||rᵢ||, two equations) with a small missing effect, its statistic is twice the fall
of GF when the columns are added and the system solved again, and its step is the added unknowns' values."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.doctor.catalog import with_columns
from estimator.doctor.fitting import minimise
from estimator.equations import LinearResiduals
from estimator.score_test import SCALE_STEPS_PER_OCTAVE, AddedColumnsScore, ScoreProfile, log_grid
from estimator.signals import FilterChoice
from estimator.vehicle import TyreModel

SAMPLES = 4000


def system_and_column(effect: float, seed: int) -> tuple[LinearResiduals, np.ndarray]:
    """r = A θ + b, three base unknowns, and an added column whose true coefficient is `effect`."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(2, SAMPLES, 3))
    added = rng.normal(size=(2, SAMPLES)) + 0.5 * base[..., 0]  # correlated with the base: the Schur part
    offset = -(base @ np.array([3.0, -1.0, 0.5]) + effect * added + rng.normal(size=(2, SAMPLES)))
    filters = FilterChoice(0.001, 5e-6, 30.0, 20.0, 40.0, 40.0)
    system = LinearResiduals(
        base, offset, ["a", "b", "c"], [], [], TyreModel.SPRING, filters, np.arange(SAMPLES), []
    )
    return system, added


@pytest.mark.parametrize("effect", [0.02, 0.05, -0.04])
def test_the_score_is_twice_the_objectives_fall_and_its_step_the_fit(effect: float) -> None:
    system, column = system_and_column(effect, seed=11)
    theta, objective = minimise(system, None)
    statistic, step = AddedColumnsScore(system, theta).of({"f": column})
    extended = with_columns(system, {"f": column[:, :]}, system.offset)
    solution, with_it = minimise(extended, None)
    assert statistic == pytest.approx(2.0 * (objective - with_it), rel=0.05)
    assert step[0] == pytest.approx(solution[-1], rel=0.05, abs=2e-3)


def test_a_column_the_system_already_has_scores_nothing() -> None:
    system, _ = system_and_column(0.0, seed=12)
    theta, _ = minimise(system, None)
    statistic, _ = AddedColumnsScore(system, theta).of({"again": system.matrix[..., 1]})
    assert abs(statistic) < 1e-6


def test_a_scale_is_searched_on_quarter_octaves_between_its_ends() -> None:
    grid = log_grid(0.001, 0.008)
    assert grid.size == 3 * SCALE_STEPS_PER_OCTAVE + 1
    assert grid[0] == pytest.approx(np.log2(0.001)) and grid[-1] == pytest.approx(np.log2(0.008))
    assert np.allclose(np.diff(grid), 1.0 / SCALE_STEPS_PER_OCTAVE)


def test_the_profile_ranks_the_admissible_scales_and_measures_the_searchs_variation() -> None:
    """Z = T / scales, largest first among the admissible ones; V = Σ|Δ√Z| (Davies' bound's variation)."""
    profile = ScoreProfile(
        np.arange(4.0), np.array([4.0, 16.0, 9.0, 1.0]), np.array([True, False, True, True])
    )
    order, variation = profile.ranked()
    assert order == [2, 0, 3] and variation == pytest.approx(2.0 + 1.0 + 2.0)
    order, variation = profile.ranked(np.array([1.0, 1.0, 9.0, 1.0]))
    assert order == [0, 2, 3] and variation == pytest.approx(2.0 + 3.0 + 0.0)  # ties in grid order
    nowhere = ScoreProfile(profile.grid_log2, profile.statistic, np.zeros(4, dtype=bool))
    assert nowhere.ranked()[0] == [1]  # none admissible: the largest alone
