"""The goodness of fit's bootstrap truth (estimator.doctor.expected): a physically possible damper (force
non-decreasing in velocity) at identify's finest resolution, near zero velocity too.

- increasing is the least-squares isotonic regression (checked against scipy's on random sequences);
- a fitted curve that falls somewhere (the zig-zag a missing series compliance leaves) becomes a smooth curve
  that never falls, and a curve that already rises keeps its points;
- the truth of a fitted model has identify's most points, its low-speed knots refined by the same ratio
  (four to an interval from an axle's 15 points a side, none from a doctor already at the finest);
- small_nnls (the noise law's non-negative fit, one per lag-1 correlation of a stack) is scipy's nnls on each
  design, singular ones (two equal columns, as ρ = 0 gives) included.

The outcomes this is for are tested in test_doctor_independent.py (a compliant top mount is unexplained, a
damper's dead band is not).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import isotonic_regression, nnls

from estimator.damper import PiecewiseLinearCurve
from estimator.doctor.expected import plausible_truth, truth_settings
from estimator.doctor.fitting import fit
from estimator.doctor.model import LOW_SPEED_KNOTS_M_S, FitSettings, Reference, starting_structure
from estimator.identify_options import IdentifyOptions
from estimator.linear_algebra import small_nnls
from estimator.monotone import increasing, smooth_curve
from estimator.sweep import SweepSettings
from estimator.vehicle import TyreModel
from simulators.vehicle_sim import SimulationSettings, default_axle, default_quarter_car, simulate


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e4, 1e4, allow_nan=False), min_size=1, max_size=40))
def test_increasing_is_the_least_squares_isotonic_regression(values: list[float]) -> None:
    fitted = increasing(np.array(values))
    assert np.all(np.diff(fitted) >= 0.0)
    np.testing.assert_allclose(fitted, isotonic_regression(values).x, rtol=1e-9, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.booleans())
def test_small_nnls_is_scipys_nnls_on_every_design_of_the_stack(seed: int, count: int, equal: bool) -> None:
    rng = np.random.default_rng(seed)
    rows = int(rng.integers(4, 60))
    # columns of very different sizes, as the noise law's (1/p, shape/p, 1/(f·p)) are
    sizes = np.array([1.0, 1e3, 1e-2])
    designs = rng.standard_normal((count, rows, 3)) * sizes
    if equal:
        designs[0, :, 0] = designs[0, :, 1]
    target = rng.standard_normal(rows) + float(rng.uniform(-2.0, 2.0))
    coefficients, misfits = small_nnls(designs, target)
    for k in range(count):
        expected, expected_misfit = nnls(designs[k], target)
        assert np.all(coefficients[k] >= 0.0)
        assert misfits[k] == pytest.approx(expected_misfit, rel=1e-7, abs=1e-9)
        assert np.linalg.norm(designs[k] @ coefficients[k] - target) == pytest.approx(misfits[k], rel=1e-9)
        if not (equal and k == 0):  # with two equal columns the split between them is not unique
            np.testing.assert_allclose(coefficients[k] * sizes, expected * sizes, rtol=1e-6, atol=1e-9)


def test_a_curve_that_falls_becomes_one_that_does_not() -> None:
    velocity = np.linspace(-0.5, 0.5, 21)
    rising = 2000.0 * velocity + 300.0 * np.tanh(velocity / 0.05)
    zigzag = rising + np.where(np.arange(21) % 2 == 0, 250.0, -250.0) * (np.abs(velocity) > 0.1)
    assert np.any(np.diff(zigzag) < 0.0)
    dense = np.linspace(-0.6, 0.6, 2001)
    smooth = smooth_curve(PiecewiseLinearCurve(velocity, zigzag)).force(dense)
    assert np.all(np.diff(smooth) >= -1e-9)
    kept = smooth_curve(PiecewiseLinearCurve(velocity, rising))
    np.testing.assert_allclose(kept.force(velocity), rising, rtol=2e-3, atol=1.0)  # tabulated densely


def test_the_truth_has_identifys_finest_resolution_near_zero_velocity_too() -> None:
    car = default_quarter_car()
    recording = simulate(car, SimulationSettings(sweep=SweepSettings(duration_s=4.0), seed=3)).recording
    reference = Reference.of(recording, car.known, FitSettings(points=20))
    model = fit(reference, starting_structure(TyreModel.MAXWELL))
    truth = plausible_truth(model, reference)
    knots = model.system.grids_m_s[0]
    fine = truth.system.grids_m_s[0]
    spacing = LOW_SPEED_KNOTS_M_S[1] - LOW_SPEED_KNOTS_M_S[0]
    low = {round(s * k * spacing / 3, 9) for k in range(4) for s in (-1.0, 1.0)}  # 60 / 20: three to one
    assert low <= {round(float(v), 9) for v in fine}
    assert not {round(spacing / 3, 9)} <= {round(float(v), 9) for v in knots}
    assert fine.size > 2.5 * knots.size
    assert np.all(np.diff(truth.curves[0].force(np.linspace(fine[0], fine[-1], 500))) >= -1e-9)


@pytest.mark.parametrize(
    ("axle", "points", "finest", "intervals"),
    [
        (False, 15, 60, 4),
        (False, 30, 60, 2),
        (False, 40, 60, 2),
        (False, 60, 60, 1),
        (True, 15, 30, 2),
        (True, 45, 45, 1),
    ],
)
def test_the_truth_is_at_identifys_finest_its_low_speed_knots_split_as_its_points_multiply(
    axle: bool, points: int, finest: int, intervals: int
) -> None:
    """An axle's side has half identify's most points (as its defaults halve an axle's), never fewer than
    the doctor's."""
    assert IdentifyOptions.MAX_POINTS == 60
    low = LOW_SPEED_KNOTS_M_S
    vehicle = default_axle().known if axle else default_quarter_car().known
    fine = truth_settings(FitSettings(points=points), vehicle)
    assert fine.points == finest
    expected = np.linspace(low[0], low[-1], intervals * (len(low) - 1) + 1)
    np.testing.assert_allclose(fine.low_speed_knots_m_s, expected, rtol=0, atol=1e-15)
