"""identify's own input checks (issue 16): the bandwidth check runs inside identify, so every path (CLI,
job, library) refuses an undersampled recording; the damper curve's point limits live in IdentifyOptions."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.bandwidth import InsufficientBandwidthError
from estimator.errors import InvalidValueError, UserError
from estimator.identify import IdentifyOptions, identify
from estimator.recording import Recording
from tests.estimator.cases import quarter_car_case

FAST = IdentifyOptions(output_error=False, intervals=False)


def decimated(recording: Recording, step: int) -> Recording:
    return Recording(
        recording.time_s[::step].copy(),
        {name: values[::step].copy() for name, values in recording.channels.items()},
        dict(recording.metadata),
    )


def test_identify_refuses_a_recording_on_a_20_Hz_grid() -> None:
    case = quarter_car_case(0)
    coarse = decimated(case.result.recording, 50)  # 1 kHz -> 20 Hz: one sample per period of the top
    with pytest.raises(InsufficientBandwidthError, match=r"sample grid is 20\.0 Hz") as caught:
        identify(coarse, case.vehicle.known, FAST)
    assert isinstance(caught.value, UserError)


def test_identify_warns_on_a_marginal_grid_and_still_identifies() -> None:
    case = quarter_car_case(0)
    marginal = decimated(case.result.recording, 8)  # 125 Hz: 6.25 samples per period of 20 Hz
    result = identify(marginal, case.vehicle.known, FAST)
    assert any("125.0 Hz" in warning for warning in result.warnings), result.warnings
    assert np.all(np.isfinite(result.curves[0].curve.force_N))


@pytest.mark.parametrize("points", [IdentifyOptions.MIN_POINTS - 1, IdentifyOptions.MAX_POINTS + 1, 0])
def test_curve_points_outside_the_limits_are_refused_naming_the_field(points: int) -> None:
    with pytest.raises(InvalidValueError, match="points must lie between 5") as caught:
        IdentifyOptions(points=points)
    assert caught.value.field == "points"


@pytest.mark.parametrize("points", [None, IdentifyOptions.MIN_POINTS, IdentifyOptions.MAX_POINTS])
def test_curve_points_within_the_limits_are_taken(points: int | None) -> None:
    assert IdentifyOptions(points=points).points == points
