"""The verdict: pass / check / fail from the lane figures, against the thresholds, with reasons."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.verdict import ThresholdsError, VerdictThresholds, judge, relative_difference_percent


def corner(eusama: float | None, phase: float | None) -> dict[str, float | None]:
    return {"eusama_percent": eusama, "phase_shift_min_deg": phase}


def expected(eusama: float, phase: float, limits: VerdictThresholds) -> str:
    if phase < limits.phase_fail_below_deg or eusama < limits.eusama_fail_below_percent:
        return "fail"
    return "check" if eusama < limits.eusama_pass_from_percent else "pass"


def test_corners_drawn_at_random_get_the_outcome_the_bands_say() -> None:
    rng = np.random.default_rng(17)
    limits = VerdictThresholds()
    outcomes = {"pass": 0, "check": 0, "fail": 0}
    for _ in range(500):
        eusama, phase = float(rng.uniform(0, 100)), float(rng.uniform(0, 90))
        verdict = judge(corner(eusama, phase), limits)
        assert verdict.outcome.value == expected(eusama, phase, limits)
        assert (verdict.outcome.value == "pass") == (not verdict.reasons)
        outcomes[verdict.outcome.value] += 1
    assert min(outcomes.values()) > 50  # every outcome was exercised


def test_the_defaults_and_their_edges() -> None:
    assert judge(corner(40.0, 35.0)).outcome == "pass"  # at the limits: sufficient
    assert judge(corner(39.9, 60.0)).outcome == "check"
    assert judge(corner(19.9, 60.0)).outcome == "fail"
    verdict = judge(corner(55.0, 34.0))
    assert verdict.outcome == "fail" and verdict.reasons == ["least phase shift 34.0° below 35°"]
    missing = judge(corner(None, 50.0))
    assert missing.outcome == "check" and "could not be estimated" in missing.reasons[0]


def test_an_axle_is_judged_per_side_and_on_its_imbalance() -> None:
    even = {"left": corner(60.0, 50.0), "right": corner(55.0, 50.0), "imbalance": {}}
    assert relative_difference_percent(60.0, 55.0) == pytest.approx(8.333, abs=1e-3)
    assert judge(even).outcome == "pass"
    uneven = {"left": corner(60.0, 50.0), "right": corner(50.0, 50.0)}  # 16.7%: check
    verdict = judge(uneven)
    assert verdict.outcome == "check" and verdict.reasons == ["left/right EUSAMA differ by 16.7% (> 15%)"]
    worse = {"left": corner(60.0, 50.0), "right": corner(45.0, 30.0)}
    verdict = judge(worse)
    assert verdict.outcome == "fail"
    assert verdict.reasons == [
        "right: least phase shift 30.0° below 35°",
        "left/right EUSAMA differ by 25.0% (> 20%)",
    ]


def test_a_site_sets_its_own_thresholds_and_the_verdict_names_them() -> None:
    strict = VerdictThresholds.from_table({"version": "lane-7 2027", "phase_fail_below_deg": 40})
    verdict = judge(corner(55.0, 38.0), strict).as_dict()
    assert verdict["outcome"] == "fail" and verdict["thresholds_version"] == "lane-7 2027"
    assert verdict["thresholds"]["phase_fail_below_deg"] == 40


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"phase_limit": 30}, "unknown key 'phase_limit'"),
        ({"eusama_fail_below_percent": 50}, "must not exceed eusama_pass_from_percent"),
        ({"phase_fail_below_deg": "thirty"}, "must be a finite number"),
        ({"version": " "}, "version must not be empty"),
    ],
)
def test_bad_thresholds_are_refused_by_name(table: dict[str, object], message: str) -> None:
    with pytest.raises(ThresholdsError, match=message):
        VerdictThresholds.from_table(table)
