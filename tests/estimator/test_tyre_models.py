"""The paper's qualitative result (Fig. 6): on data made with a Maxwell tyre, identifying with the Maxwell
model is clearly better than with Kelvin-Voigt or constant stiffness."""

from __future__ import annotations

import pytest
from cases import curve_error_percent, quarter_car_case

from estimator.identify import IdentifyOptions, identify
from estimator.vehicle import TyreModel

SEEDS = range(101, 105)
CLEARLY_BETTER = 0.8
"""Maxwell's curve error must be at most this fraction of the better of the two simpler models' errors."""


@pytest.mark.parametrize("seed", SEEDS)
def test_maxwell_identification_beats_kelvin_voigt_and_spring(seed: int, hit_rate) -> None:
    case = quarter_car_case(seed)
    truth = case.truths[0]
    errors, gaps = {}, {}
    for tyre in TyreModel:
        result = identify(case.result.recording, case.vehicle.known, IdentifyOptions(tyre=tyre))
        errors[tyre] = curve_error_percent(result.curves[0].curve, truth, result.system.velocity_m_s[0])
        gaps[tyre] = result.gap_m
    others = min(errors[TyreModel.KELVIN_VOIGT], errors[TyreModel.SPRING])
    hit = errors[TyreModel.MAXWELL] <= CLEARLY_BETTER * others
    hit_rate(
        "Fig. 6: Maxwell clearly better than Kelvin-Voigt and constant stiffness",
        f"{case.name}: curve error "
        + ", ".join(f"{t.value} {e:.2f}%" for t, e in errors.items())
        + "; output-error gap "
        + ", ".join(f"{t.value} {g * 1e6:.1f} µm" for t, g in gaps.items()),
        hit,
    )
    assert hit, errors
    assert gaps[TyreModel.MAXWELL] < min(gaps[TyreModel.KELVIN_VOIGT], gaps[TyreModel.SPRING])
