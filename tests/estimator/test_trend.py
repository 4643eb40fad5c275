"""The damping trend (estimator.trend): forces read off piecewise-linear curves at reference velocities,
None outside a curve's range, and the change since the first test that reaches each velocity."""

from __future__ import annotations

import pytest

from estimator.trend import change_percent, damping_trend, force_at


def test_force_is_interpolated_inside_the_curve_and_none_outside() -> None:
    curve = ([-0.4, 0.0, 0.2, 0.6], [-800.0, 0.0, 300.0, 1100.0])
    assert force_at(curve, [-0.5, -0.1, 0.1, 0.5, 0.6, 0.7]) == [
        None,
        pytest.approx(-200.0),
        pytest.approx(150.0),
        pytest.approx(900.0),
        pytest.approx(1100.0),
        None,
    ]
    assert force_at(([], []), [0.1]) == [None]


def test_change_is_relative_to_the_first_test_that_reaches_the_velocity() -> None:
    wide = ([-0.5, 0.5], [-1000.0, 1000.0])  # F = 2000 N·s/m · v
    narrow = ([-0.2, 0.2], [-360.0, 360.0])  # 1800 N·s/m, does not reach ±0.5
    worn = ([-0.5, 0.5], [-800.0, 800.0])  # 1600 N·s/m
    tests = [{"left": narrow}, {}, {"left": wide, "right": wide}, {"left": worn}]
    left, right = damping_trend(tests, reference_m_s=(-0.5, 0.1, 0.5))
    assert (left.corner, right.corner) == ("left", "right")
    assert [p.test for p in left.points] == [0, 2, 3] and [p.test for p in right.points] == [2]
    first, second, third = left.points
    assert first.force_N == (None, pytest.approx(180.0), None)
    assert first.change_percent == (None, 0.0, None)
    assert str(left.points[1].change_percent[0]) == "0.0"  # the compression side's own first: not -0.0
    assert second.force_N == (pytest.approx(-1000.0), pytest.approx(200.0), pytest.approx(1000.0))
    # ±0.5 m/s: the first test reaching it is this one; 0.1 m/s: +11.1% since the narrow first test
    assert second.change_percent == (0.0, pytest.approx(100 * 20 / 180), 0.0)
    worn_out = (pytest.approx(-20.0), pytest.approx(100 * -20 / 180), pytest.approx(-20.0))
    assert third.change_percent == worn_out  # less force on both sides: negative on both sides
    assert right.points[0].change_percent == (0.0, 0.0, 0.0)


def test_no_change_against_nothing_or_zero() -> None:
    assert change_percent(None, 100.0) is None
    assert change_percent(100.0, None) is None
    assert change_percent(100.0, 0.0) is None
    assert change_percent(-80.0, -100.0) == pytest.approx(-20.0)  # compression force fell by a fifth
    assert change_percent(120.0, 100.0) == pytest.approx(20.0)
