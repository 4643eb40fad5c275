"""The calibration's early stop (estimator.doctor.diagnose._Doctor.calibrate): a candidate is left out of the
later bootstrap draws once the draws made rule it out, which must never change the round's decision. Every
statistic of a draw is at least 0, so the scales over all draws are at least the sum over the draws made
spread over all of them: a candidate that is not significant at those lower bounds is not significant at the
full scales either, whatever the remaining draws give."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.doctor.candidates import calibration_scales, log_p_value
from estimator.doctor.result import CandidateScore

statistic = st.floats(0.0, 1e4, allow_nan=False)


def _score(wald: float, ratio: float, unknowns: int, effect: str) -> CandidateScore:
    return CandidateScore(
        effect=effect,
        objective_ratio=0.9,
        gap_m=1e-5,
        gap_ratio=0.9,
        equation_statistic=wald,
        simulation_statistic=ratio,
        unknowns=unknowns,
        equation_p=1e-9,
        simulation_p=1e-9,
        p_value=1e-9,
        parameters={},
        verdict="tested",
    )


@settings(max_examples=300, deadline=None)
@given(
    observed=st.tuples(statistic, statistic),
    unknowns=st.integers(0, 6),
    effect=st.sampled_from(["spring_curve", "tyre_liftoff", "sensor_dynamics(x_t, lag)"]),
    draws=st.lists(st.tuples(statistic, statistic), min_size=2, max_size=12),
    made=st.integers(1, 11),
    bound=st.floats(1e-4, 0.05),
)
def test_a_candidate_ruled_out_early_is_not_significant_after_every_draw(
    observed, unknowns, effect, draws, made, bound
) -> None:
    score = _score(*observed, unknowns, effect)
    made = min(made, len(draws) - 1)
    early = ([w for w, _ in draws[:made]], [r for _, r in draws[:made]])
    full = ([w for w, _ in draws], [r for _, r in draws])
    if log_p_value(score, *calibration_scales(score, early, len(draws))) > math.log(bound):
        assert log_p_value(score, *calibration_scales(score, full)) > math.log(bound)


def test_the_lower_bound_spreads_the_sum_over_every_draw() -> None:
    score = _score(100.0, 100.0, 2, "spring_curve")
    # 3 of 8 draws made, statistics summing to 48 and 80: scales at least 48/16 = 3 and 80/16 = 5
    assert calibration_scales(score, ([16.0, 16.0, 16.0], [20.0, 30.0, 30.0]), 8) == (3.0, 5.0)
    # all made: their means over q
    assert calibration_scales(score, ([16.0, 16.0, 16.0], [20.0, 30.0, 30.0])) == (8.0, 80.0 / 6.0)
    # below 1: no scale; no finite draw: none
    assert calibration_scales(score, ([0.5], []), 8) == (1.0, 1.0)


def test_where_neither_model_simulates_the_equations_decide() -> None:
    """SimulationTest's nan (neither the current model nor the candidate can be simulated): the candidate's
    p-value, calibrated or not, is its Wald test's."""
    import math

    from estimator.distributions import log_chi_square_survival
    from estimator.doctor.candidates import calibrated

    score = _score(40.0, math.nan, 2, "spring_curve")
    assert log_p_value(score) == log_chi_square_survival(40.0, 2)
    assert log_p_value(score, 4.0, 3.0) == log_chi_square_survival(10.0, 2)
    calibrated = calibrated(score, 4.0, 3.0)
    assert calibrated.simulation_p == 0.0
    assert calibrated.p_value == calibrated.equation_p == math.exp(log_chi_square_survival(10.0, 2))
