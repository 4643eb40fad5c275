"""Each test of the doctor's procedure (estimator.doctor.criteria) on synthetic statistics whose truth is
known: under a null drawn with a fixed seed it rejects at about its nominal rate α (the observed rate's 95%
Clopper-Pearson interval holds α, or the exact size where the test knowingly differs), and under a clear
alternative it rejects.

- EquationTest: the Wald test with the sandwich covariance of the paper's objective, on a linear system of
  two equations with white residuals, as many samples as the doctor selects (DiagnoseOptions.nsample);
- SimulationTest: the likelihood ratio of a gap, on nested least-squares fits of white noise;
- Selection: Bonferroni over a round's candidates: the chance of naming anything when nothing is missing;
- GoodnessOfFit: the prediction interval of a gap among bootstrap draws of the same model;
- ScaleSearch: Davies' bound for the largest Wald statistic along a searched scale, on a smooth χ² process.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from estimator.doctor.criteria import (
    ALPHA,
    EachMember,
    EquationTest,
    GoodnessOfFit,
    ScaleSearch,
    Selection,
    SimulationTest,
    intersection_union,
)
from estimator.doctor.criteria import TestResult as Outcome  # pytest would take a Test… class for tests
from estimator.doctor.diagnose import DiagnoseOptions
from estimator.doctor.fitting import minimise
from estimator.equations import LinearResiduals
from estimator.signals import FilterChoice
from estimator.vehicle import TyreModel

SAMPLE_TIME_S = 0.001
SELECTED_EVERY = 5
"""The doctor's equations use every fifth sample or so (nsample 5000 of a 25 s, 1 kHz recording)."""
FILTERS = FilterChoice(SAMPLE_TIME_S, 5e-6, 30.0, 20.0, 40.0, 40.0)


def rejection_interval(rejections: int, draws: int) -> tuple[float, float]:
    """95% Clopper-Pearson interval of a rejection rate."""
    interval = stats.binomtest(rejections, draws).proportion_ci(0.95)
    return float(interval.low), float(interval.high)


def linear_system(rng: np.random.Generator, samples: int, effect: float) -> LinearResiduals:
    """r = A θ + b with a base unknown `m` (true value 3) and a family of two unknowns f1, f2 (true values
    `effect` and 0) in two equations, white unit residuals."""
    base = rng.normal(size=(2, samples, 1))
    family = rng.normal(size=(2, samples, 2))
    noise = rng.normal(size=(2, samples))
    offset = -(3.0 * base[..., 0] + family @ np.array([effect, 0.0]) + noise)
    return LinearResiduals(
        np.concatenate([base, family], axis=2),
        offset,
        ["m", "f1", "f2"],
        [],
        [],
        TyreModel.SPRING,
        FILTERS,
        np.arange(samples) * SELECTED_EVERY,
        [],
    )


def wald(system: LinearResiduals) -> Outcome:
    theta, _ = minimise(system, None)
    family = [system.parameter_names.index(n) for n in ("f1", "f2")]
    return EquationTest().test(system, theta, family, SAMPLE_TIME_S)


def test_the_equation_test_holds_its_size_and_finds_a_family() -> None:
    rng = np.random.default_rng(11)
    samples = DiagnoseOptions().nsample or 5000
    null = [wald(linear_system(rng, samples, 0.0)) for _ in range(300)]
    assert all(t.unknowns == 2 for t in null)
    rejections = sum(t.p_value < ALPHA for t in null)
    low, high = rejection_interval(rejections, len(null))
    print(f"Wald test under the null: {rejections}/{len(null)} rejections at α = {ALPHA}")
    assert low <= ALPHA <= high
    found = [wald(linear_system(rng, samples, 0.1)) for _ in range(10)]
    assert all(t.p_value < 1e-6 for t in found)


def test_the_equation_test_of_no_unknown_rejects_nothing() -> None:
    system = linear_system(np.random.default_rng(3), 2000, 0.05)
    assert EquationTest().test(system, minimise(system, None)[0], [], SAMPLE_TIME_S) == Outcome(0.0, 0, 1.0)


def gaps(rng: np.random.Generator, samples: int, unknowns: int, effect: float) -> tuple[float, float]:
    """The RMS residual of white noise (plus `effect` times the first regressor) without and with
    `unknowns` regressors fitted by least squares."""
    columns = rng.normal(size=(samples, unknowns))
    y = rng.normal(size=samples) + effect * columns[:, 0]
    fitted = columns @ np.linalg.lstsq(columns, y, rcond=None)[0]
    return float(np.sqrt(np.mean(y**2))), float(np.sqrt(np.mean((y - fitted) ** 2)))


@pytest.mark.parametrize("unknowns", [1, 5])
def test_the_simulation_test_holds_its_size_and_finds_an_effect(unknowns: int) -> None:
    rng = np.random.default_rng(5 + unknowns)
    samples, draws = 2000, 2000
    test = SimulationTest()
    null = [test.test(samples, *gaps(rng, samples, unknowns, 0.0), unknowns) for _ in range(draws)]
    rejections = sum(t.p_value < ALPHA for t in null)
    low, high = rejection_interval(rejections, draws)
    print(f"likelihood ratio, {unknowns} unknowns: {rejections}/{draws} rejections at α = {ALPHA}")
    assert low <= ALPHA <= high
    found = [test.test(samples, *gaps(rng, samples, unknowns, 0.2), unknowns) for _ in range(10)]
    assert all(t.p_value < 1e-6 for t in found)


def test_the_simulation_test_of_diverged_models() -> None:
    test = SimulationTest()
    assert test.test(1000, 1e-4, math.inf, 2).p_value == 1.0  # the family makes the model diverge
    assert test.test(1000, math.inf, 1e-4, 2).p_value == 0.0  # it keeps a diverging model bounded
    # neither simulates (a starting model fitted from rates stated far off, lab rig 4): the simulation says
    # nothing against the family, so the equation test decides the intersection-union p-value
    neither = test.test(1000, math.inf, math.inf, 2)
    assert math.isnan(neither.statistic) and neither.p_value == 0.0
    assert intersection_union(Outcome(4163.0, 5, 1e-12), neither) == 1e-12
    assert test.test(1000, 1e-4, 2e-4, 2).p_value == 1.0  # a larger gap is no evidence for it
    assert test.test(1000, 1e-4, 1e-4, 0).unknowns == 1  # an effect without unknowns: one degree


def test_a_candidate_is_significant_only_when_both_tests_are() -> None:
    assert intersection_union(Outcome(50.0, 2, 1e-9), Outcome(0.5, 2, 0.4)) == 0.4
    assert intersection_union(Outcome(50.0, 2, 1e-9), Outcome(40.0, 2, 1e-8)) == 1e-8


@pytest.mark.parametrize("candidates", [1, 4, 14])
def test_selection_names_nothing_missing_at_most_alpha_of_the_time(candidates: int) -> None:
    rng = np.random.default_rng(candidates)
    draws = 4000
    selection = Selection()
    named = sum(
        selection.choose(
            {(f"family {k}",): math.log(p) for k, p in enumerate(rng.uniform(size=candidates))}, candidates
        )
        is not None
        for _ in range(draws)
    )
    low, _ = rejection_interval(named, draws)
    print(f"{candidates} candidates: named something in {named}/{draws} rounds with nothing missing")
    assert low <= ALPHA and named / draws <= ALPHA + 0.01  # Bonferroni: at most α


def test_selection_names_the_most_significant_candidate() -> None:
    """Selection takes log p-values: two large effects whose p-values both underflow to 0 are still
    ranked."""
    selection = Selection()
    bound = ALPHA / 3

    def log(p_values: dict[str, float]) -> dict[tuple, float]:
        return {(k,): math.log(p) for k, p in p_values.items()}

    def choose(log_p: dict[tuple, float]) -> str | None:
        chosen = selection.choose(log_p, len(log_p))
        return None if chosen is None else chosen[0]

    assert choose(log({"a": 0.5, "b": 1e-8, "c": 1e-5})) == "b"
    assert choose(log({"a": 0.5, "b": 1.01 * bound, "c": 0.9})) is None
    assert choose(log({"a": 0.5, "b": 0.99 * bound, "c": 0.9})) == "b"
    assert choose(log({"b": 1e-9, "a": 1e-9})) == "a"  # a tie: by name, whatever the order
    assert choose({("a",): -900.0, ("b",): -1200.0, ("c",): 0.0}) == "b"  # both p-values underflow
    assert choose({}) is None
    assert Selection(alpha=0.01).choose(log({"a": 0.02, "b": 0.006}), 2) is None  # α/m = 0.005


def test_families_together_wait_for_their_members_unless_they_beat_the_winner_on_p_and_likelihood() -> None:
    """Nested models, the smaller first: the load path's families together wait while one alone is
    significant. Where they beat the winner (a sensor family standing in for two wrong rates in series) on
    p-value and on likelihood (the smaller free-simulation gap), their most significant member is named
    instead; where the winner simulates better, it is named. Every candidate is held to α/m."""
    selection, bound = Selection(), ALPHA / 4
    pair, spring, tyre, gain = ("spring", "tyre"), ("spring",), ("tyre",), ("gain",)
    log_p = {spring: math.log(0.5 * bound), tyre: math.log(0.9), gain: -30.0, pair: -50.0}
    gap_m = {spring: 1.0e-3, tyre: 2.0e-3, gain: 1.4e-3, pair: 0.4e-3}
    assert selection.choose(log_p, 4) == gain  # no gaps given: the pair waits for spring
    assert selection.choose(log_p, 4, gap_m) == spring  # the pair beats the gain on p and likelihood
    log_p[tyre] = math.log(0.1 * bound)
    assert selection.choose(log_p, 4, gap_m) == tyre  # both members significant: the more so
    log_p[tyre] = math.log(0.9)
    gap_m[gain] = 0.1e-3
    assert selection.choose(log_p, 4, gap_m) == gain  # the gain simulates better: it is named
    gap_m[gain], log_p[pair] = 1.4e-3, -20.0
    assert selection.choose(log_p, 4, gap_m) == gain  # the gain beats the pair on p
    log_p[pair], log_p[gain] = -50.0, math.log(0.01 * bound)
    assert selection.choose(log_p, 4, gap_m) == spring
    log_p[spring] = math.log(1.01 * bound)
    assert selection.choose(log_p, 4, gap_m) == pair  # neither alone is significant: the pair
    log_p[spring], log_p[gain] = -60.0, -70.0
    assert selection.choose(log_p, 4, gap_m) == gain  # the winner is the gain, and the pair does not beat it
    log_p[gain] = math.log(1.01 * bound)
    log_p[pair] = math.log(1.01 * bound)
    log_p[spring] = math.log(1.01 * bound)
    assert selection.choose(log_p, 4, gap_m) is None


def test_selection_with_families_together_keeps_the_family_wise_error_at_most_alpha() -> None:
    """Nothing missing (every p-value uniform, every gap random): a round of 13 families and one load path of
    two of them names something at most α of the time, as Bonferroni over the 14 would, whether the path
    gives way to a member or not."""
    rng, draws, selection = np.random.default_rng(29), 4000, Selection()
    named = 0
    for _ in range(draws):
        p, gaps = rng.uniform(size=14), rng.uniform(size=14)
        log_p = {(f"family {k}",): math.log(v) for k, v in enumerate(p[:13])}
        log_p[("family 0", "family 1")] = math.log(p[13])
        named += selection.choose(log_p, 14, dict(zip(log_p, gaps, strict=True))) is not None
    low, _ = rejection_interval(named, draws)
    print(f"a load path among 13 families: named something in {named}/{draws} rounds with nothing missing")
    assert low <= ALPHA and named / draws <= ALPHA + 0.01


def test_a_member_the_others_make_redundant_is_not_named_with_them() -> None:
    """Two families named together, f1 acting and f2 not (one unknown each): f2 is found redundant about
    1 − α of the time (its Wald test given f1 holds its size), f1 never."""
    rng, draws = np.random.default_rng(29), 200
    redundant = {"f1": 0, "f2": 0}
    for _ in range(draws):
        system = linear_system(rng, 2000, 0.2)
        theta, _ = minimise(system, None)
        for name in redundant:
            index = {name: [system.parameter_names.index(name)]}
            redundant[name] += EachMember().redundant(system, theta, index, SAMPLE_TIME_S) is not None
    low, high = rejection_interval(draws - redundant["f2"], draws)
    print(f"f2 (not acting) found redundant {redundant['f2']}/{draws}, f1 (acting) {redundant['f1']}/{draws}")
    assert redundant["f1"] == 0 and low <= ALPHA <= high
    both = {"f1": [1], "f2": [2]}
    assert "f2 adds nothing given the others" in str(
        EachMember(alpha=1e-9).redundant(system, theta, both, 1e-3)
    )


@pytest.mark.parametrize("draws", [DiagnoseOptions().draws, 40])
def test_the_goodness_of_fit_false_alarm_rate(draws: int) -> None:
    """A gap drawn like the bootstrap's own (log-normal, as the gaps of refitted models are): "unexplained"
    about α of the time. The prediction interval uses the normal quantile where the exact one is Student's
    t with draws − 1 degrees of freedom, so with few draws the size is that of t (7.1% at 8 draws), and α
    with many."""
    rng = np.random.default_rng(draws)
    test = GoodnessOfFit()
    trials = 3000
    alarms = 0
    for _ in range(trials):
        sample = np.exp(rng.normal(math.log(30e-6), 0.2, draws + 1))
        alarms += test.unexplained(test.p_value(float(sample[0]), list(sample[1:])))
    exact_t = float(stats.t.sf(stats.norm.isf(ALPHA), draws - 1))
    low, high = rejection_interval(alarms, trials)
    print(f"goodness of fit, {draws} draws: {alarms}/{trials} false alarms (Student's t size {exact_t:.3f})")
    assert low <= max(ALPHA, exact_t) and high >= min(ALPHA, exact_t)
    assert alarms / trials <= 0.08


def test_the_goodness_of_fit_finds_a_gap_beyond_its_draws() -> None:
    test = GoodnessOfFit()
    draws = list(np.exp(np.random.default_rng(2).normal(math.log(30e-6), 0.2, 8)))
    assert test.unexplained(test.p_value(90e-6, draws))  # three times the draws' gap
    assert not test.unexplained(test.p_value(30e-6, draws))
    assert test.p_value(math.inf, draws) == 0.0  # the final model diverges
    assert test.p_value(30e-6, [math.inf, 25e-6]) == 0.0  # its own re-identifications diverge
    assert test.p_value(20e-6, draws) > test.p_value(40e-6, draws)


def test_a_statistic_whose_half_underflows_has_p_one() -> None:
    """The smallest positive float (a draw's statistic can be that): ln P = 0, not a math domain error."""
    from estimator.distributions import log_chi_square_survival

    assert log_chi_square_survival(5e-324, 2) == 0.0
    assert log_chi_square_survival(5e-324, 3) == 0.0


def searched_wald(rng: np.random.Generator, grid: np.ndarray, effect: float) -> tuple[float, float]:
    """The largest W along a scale grid, and the total variation of √W: W(θ) = |Z(θ)|², Z's two components
    smooth Gaussian processes of unit variance (white noise through a kernel half an octave wide), plus
    `effect` in the first at θ = 0 (the true scale)."""
    centres = np.linspace(grid[0] - 1.0, grid[-1] + 1.0, 200)
    kernel = np.exp(-0.5 * np.square((grid[:, None] - centres[None, :]) / 0.5))
    kernel /= np.linalg.norm(kernel, axis=1, keepdims=True)
    z = kernel @ rng.normal(size=(centres.size, 2))
    z[:, 0] += effect * kernel @ kernel[np.argmin(np.abs(grid))]
    w = np.sum(z**2, axis=1)
    return float(w.max()), float(np.sum(np.abs(np.diff(np.sqrt(w)))))


def test_a_searched_scale_holds_its_size_where_the_pointwise_test_does_not() -> None:
    """Over six octaves searched on quarter octaves (as fitting.score_profile does), the χ² p-value of the
    largest W rejects far more often than α; Davies' bound at most α (it is an upper bound), and it still
    finds a clear effect at one scale."""
    rng = np.random.default_rng(29)
    grid, draws = np.linspace(-3.0, 3.0, 25), 2000
    null = [searched_wald(rng, grid, 0.0) for _ in range(draws)]
    pointwise = sum(ScaleSearch().log_p(w, 2) < math.log(ALPHA) for w, _ in null)
    davies = sum(ScaleSearch(v).log_p(w, 2) < math.log(ALPHA) for w, v in null)
    print(f"searched scale: pointwise {pointwise}/{draws}, Davies {davies}/{draws} rejections at α = {ALPHA}")
    assert rejection_interval(pointwise, draws)[0] > 2 * ALPHA
    assert rejection_interval(davies, draws)[0] <= ALPHA
    assert davies > 0  # a bound, not a test that never rejects
    found = [searched_wald(rng, grid, 8.0) for _ in range(100)]
    assert sum(ScaleSearch(v).log_p(w, 2) < math.log(ALPHA) for w, v in found) >= 95


def test_an_unsearched_scale_is_the_chi_square_test() -> None:
    assert ScaleSearch(0.0).log_p(9.0, 2) == pytest.approx(math.log(stats.chi2.sf(9.0, 2)))
    assert ScaleSearch(3.0).log_p(9.0, 2) > ScaleSearch(0.0).log_p(9.0, 2)
    assert ScaleSearch(3.0).log_p(0.0, 2) == 0.0 and ScaleSearch(50.0).log_p(0.5, 1) == 0.0
