"""Must show: from a vehicle file that states only the mass, on simulated recordings with 5 µm sensor noise
and the real SUV damper table of ../shared/realdata (not of the tanh form), the damper curve comes out within
2% of peak force, the sprung and unsprung masses within 2% and the spring and tyre stiffnesses within 5% in
at least 90% of vehicles drawn at random (mass, sprung share, stiffnesses, tyre damping and relaxation time,
damper scale), both at the bench's 1 kHz and at 500 Hz (a recording from another rig, identified as it is).
Every figure is printed in the test summary.

Also: the joint search over ϑ reaches the optimum of a plain scan of exact solves; a ϑ stated for 1 ms is
right for a 500 Hz recording; `free` re-identifies stated (wrong) values; the axle identifies one spring and
one tyre stiffness from the mass alone."""

from __future__ import annotations

import importlib
from dataclasses import replace

import numpy as np
import pytest
from cases import (
    axle_case_at,
    identification_errors,
    mass_only,
    wide_quarter_car_case,
)

from estimator.equations import build
from estimator.errors import InvalidValueError
from estimator.identify import STARTING_RELAXATION_TIME_S, IdentifyOptions, identify, identify_unstated
from estimator.relaxation import fit_relaxation_time
from estimator.solvers.exact import solve_exact
from estimator.vehicle import (
    ModelKind,
    TyreModel,
    VehicleConstant,
    VehicleParameters,
    coefficient_from_relaxation_time,
)

DRAWS = [int(seed) for seed in np.random.default_rng(2026).integers(1_000, 1_000_000, size=10)]
"""Ten vehicles drawn at random (the draw itself seeded, so the test is reproducible)."""
CURVE_TOLERANCE_PERCENT = 2.0
MASS_TOLERANCE_PERCENT = 2.0
STIFFNESS_TOLERANCE_PERCENT = 5.0
REQUIRED_HIT_RATE = 0.9
OPTIONS = IdentifyOptions(output_error=False)


def _hit(errors: dict[str, float]) -> bool:
    curves = [v for k, v in errors.items() if k.startswith("curve")]
    return (
        max(curves) <= CURVE_TOLERANCE_PERCENT
        and max(errors["sprung mass"], errors["unsprung mass"]) <= MASS_TOLERANCE_PERCENT
        and max(errors["spring"], errors["tyre"]) <= STIFFNESS_TOLERANCE_PERCENT
    )


def _describe(errors: dict[str, float]) -> str:
    return ", ".join(f"{name} {value:.2f}%" for name, value in errors.items())


def _mass_only_experiment(sample_time_s: float, hit_rate, experiment: str) -> None:
    hits = 0
    for seed in DRAWS:
        case = wide_quarter_car_case(seed, sample_time_s)
        result = identify(case.result.recording, mass_only(case.vehicle.known), OPTIONS)
        assert result.identified == {VehicleConstant.SPRING, VehicleConstant.TYRE, VehicleConstant.THETA}
        errors = identification_errors(case, result)
        hit = _hit(errors)
        hits += hit
        hit_rate(experiment, f"{case.name}: {_describe(errors)}", hit)
    assert hits / len(DRAWS) >= REQUIRED_HIT_RATE, f"{hits}/{len(DRAWS)}"


def test_mass_only_quarter_car_at_1_kHz(hit_rate) -> None:
    _mass_only_experiment(
        0.001, hit_rate, "mass-only vehicle file, 1 kHz: curve 2%, masses 2%, stiffnesses 5% (>= 90%)"
    )


def test_mass_only_quarter_car_at_500_Hz(hit_rate) -> None:
    _mass_only_experiment(
        0.002, hit_rate, "mass-only vehicle file, 500 Hz: curve 2%, masses 2%, stiffnesses 5% (>= 90%)"
    )


def test_joint_search_reaches_the_optimum_of_a_scan_of_exact_solves() -> None:
    """The profile min_θ GF(θ, τ), scanned by exact solves on a grid of τ, is nowhere below what the joint
    search found, and the search's τ lies within one grid step of the scan's best."""
    case = wide_quarter_car_case(DRAWS[0])
    start = mass_only(case.vehicle.known).with_relaxation_time(STARTING_RELAXATION_TIME_S)
    system = build(case.result.recording, start, TyreModel.MAXWELL, nsample=2000)
    fit = fit_relaxation_time(system)
    grid = np.geomspace(0.005, 0.12, 25)
    dt = case.result.recording.sample_time_s
    solutions = [
        solve_exact(system.with_tyre_theta(coefficient_from_relaxation_time(tau, dt)), certify=False)
        for tau in grid
    ]
    scan = [solution.objective for solution in solutions]
    assert fit.solution.objective <= min(scan) * (1 + 1e-7)
    best = int(np.argmin(scan))
    assert grid[max(best - 1, 0)] <= fit.relaxation_time_s <= grid[min(best + 1, grid.size - 1)]
    assert fit.solution.certified_gap < 1e-3


def test_theta_is_referred_to_1_ms_whatever_the_sample_time() -> None:
    """The paper's γ = C_d/(K_d·Δt): ϑ = 0.97 stated for 1 ms is τ = 32.3 ms, which at Δt = 2 ms is
    γ = 16.2 and ϑ = 0.942. A 500 Hz recording identified with the complete vehicle file (ϑ for 1 ms) is as
    accurate as at 1 kHz, and ϑ identified from the mass alone, reported for 1 ms, is the same at both
    rates."""
    vehicle = VehicleParameters(ModelKind.QUARTER_CAR, 400.0, 25e3, 200e3, 0.97)
    relaxation_time = 0.001 * 0.97 / (1 - 0.97)
    gamma = relaxation_time / 0.002
    assert vehicle.viscoelastic_coefficient_at(0.002) == pytest.approx(gamma / (1 + gamma), rel=1e-12)
    assert vehicle.viscoelastic_coefficient_at(0.001) == pytest.approx(0.97, rel=1e-12)

    seed = DRAWS[1]
    fast, slow = wide_quarter_car_case(seed, 0.001), wide_quarter_car_case(seed, 0.002)
    stated = identify(slow.result.recording, slow.vehicle.known, OPTIONS)
    errors = identification_errors(slow, stated)
    assert errors["curve single"] <= CURVE_TOLERANCE_PERCENT
    assert errors["sprung mass"] <= MASS_TOLERANCE_PERCENT
    thetas = [
        identify(case.result.recording, mass_only(case.vehicle.known), OPTIONS).model.vehicle
        for case in (fast, slow)
    ]
    truth = fast.vehicle.known.tyre_relaxation_time_s
    for found in thetas:
        assert found.tyre_relaxation_time_s == pytest.approx(truth, rel=0.1)
    assert thetas[0].tyre_viscoelastic_coefficient == pytest.approx(
        thetas[1].tyre_viscoelastic_coefficient, abs=0.005
    )


def test_free_identifies_stated_values_and_without_it_they_are_used() -> None:
    case = wide_quarter_car_case(DRAWS[2])
    truth = case.vehicle.known
    wrong = replace(
        truth,
        spring_stiffness_N_per_m=1.3 * truth.spring_stiffness_N_per_m,
        tyre_stiffness_N_per_m=0.7 * truth.tyre_stiffness_N_per_m,
        tyre_viscoelastic_coefficient=0.9,
    )
    recording = case.result.recording
    used = identify(recording, wrong, OPTIONS)
    assert used.identified == frozenset()
    assert used.model.vehicle == wrong
    every = frozenset({VehicleConstant.SPRING, VehicleConstant.TYRE, VehicleConstant.THETA})
    freed = identify(recording, wrong, replace(OPTIONS, free=every))
    errors = identification_errors(case, freed)
    assert _hit(errors), errors
    assert freed.to_json()["stiffness_N_per_m"]["identified"] == ["spring", "tyre"]
    assert freed.to_json()["tyre_viscoelastic_identified"] is True
    with pytest.raises(ValueError, match="axle only"):
        identify(recording, wrong, replace(OPTIONS, free=frozenset({VehicleConstant.BAR})))


def test_identify_unstated_finds_theta_with_the_rates_free_and_keeps_the_stated_rates(monkeypatch) -> None:
    """identify_unstated (the model doctor's start): ϑ from a fit with the stated rates free, so that a tyre
    rate stated 40% low does not pull it to a Maxwell element that relaxes slowly enough to act as the
    missing spring (identify with the rate held does); the stated rates kept. Where the free fit cannot
    determine the rates, ϑ comes from the fit with them held."""
    case = wide_quarter_car_case(DRAWS[2])
    truth, recording = case.vehicle.known, case.result.recording
    wrong = replace(
        truth, tyre_stiffness_N_per_m=0.6 * truth.tyre_stiffness_N_per_m, tyre_viscoelastic_coefficient=None
    )
    rates = frozenset({VehicleConstant.SPRING, VehicleConstant.TYRE})
    started = identify_unstated(recording, wrong, rates)
    freed = identify(recording, wrong, replace(OPTIONS, free=rates, intervals=False)).model.vehicle
    held = identify(recording, wrong, replace(OPTIONS, intervals=False)).model.vehicle
    assert started == replace(wrong, tyre_viscoelastic_coefficient=freed.tyre_viscoelastic_coefficient)
    true_tau, tau = truth.tyre_relaxation_time_s, started.tyre_relaxation_time_s
    assert true_tau is not None and tau == pytest.approx(true_tau, rel=0.2)
    assert held.tyre_relaxation_time_s > 3 * true_tau  # what the doctor started from before

    def undetermined(recording, vehicle, options):  # type: ignore[no-untyped-def]
        if options.free:
            raise InvalidValueError("the identified tyre_stiffness_N_per_m is -1, not positive")
        return identify(recording, vehicle, options)

    monkeypatch.setattr(importlib.import_module("estimator.identify"), "identify", undetermined)
    assert identify_unstated(recording, wrong, rates) == held


@pytest.mark.parametrize("tyre", [TyreModel.KELVIN_VOIGT, TyreModel.SPRING])
def test_tyre_models_without_theta_identify_the_stiffnesses_and_need_no_theta(tyre: TyreModel) -> None:
    """Kelvin-Voigt and constant-stiffness tyres need no ϑ: from the mass alone they give stiffnesses (and
    null ϑ in the JSON)."""
    case = wide_quarter_car_case(DRAWS[3])
    result = identify(case.result.recording, mass_only(case.vehicle.known), replace(OPTIONS, tyre=tyre))
    assert result.identified == {VehicleConstant.SPRING, VehicleConstant.TYRE}
    assert result.model.vehicle.tyre_viscoelastic_coefficient is None
    assert result.to_json()["tyre_viscoelastic_coefficient"] is None
    errors = identification_errors(case, result)
    alone = mass_only(case.vehicle.known)
    maxwell = identification_errors(case, identify(case.result.recording, alone, OPTIONS))
    # data made with a Maxwell tyre: the simpler model's constants are biased (24% on the spring here),
    # the Maxwell model's are not (the paper's Fig. 6, for the stiffnesses)
    assert all(np.isfinite(value) for value in errors.values())
    assert maxwell["spring"] < errors["spring"] and maxwell["curve single"] < errors["curve single"]


AXLE_SEEDS = (201, 202, 203)


@pytest.mark.parametrize("sample_time_s", [0.001, 0.002])
def test_axle_from_mass_track_and_bar(sample_time_s: float, hit_rate) -> None:
    """An axle file with mass, track and anti-roll bar: one spring and one tyre stiffness for both sides
    and ϑ identified, with unequal real dampers left and right."""
    hits = 0
    for seed in AXLE_SEEDS:
        case = axle_case_at(seed, sample_time_s)
        result = identify(case.result.recording, mass_only(case.vehicle.known), OPTIONS)
        errors = identification_errors(case, result)
        hit = _hit(errors)
        hits += hit
        hit_rate(
            f"mass-only axle file (track and bar stated), {1 / sample_time_s:.0f} Hz: "
            "curves 2%, masses 2%, stiffnesses 5%",
            f"{case.name}: {_describe(errors)}",
            hit,
        )
    assert hits >= len(AXLE_SEEDS) - 1


def test_axle_anti_roll_bar_can_be_freed_too() -> None:
    """`free` bar: the bar is one more linear unknown. It trades off partly with the spring (both act on the
    suspension deflections): measured on this axle, bar 5.5% and spring 4.4% off, so the bound is 10%."""
    case = axle_case_at(AXLE_SEEDS[0], 0.001)
    options = replace(OPTIONS, free=frozenset({VehicleConstant.BAR}))
    result = identify(case.result.recording, mass_only(case.vehicle.known), options)
    stiffness = result.to_json()["stiffness_N_per_m"]
    assert stiffness["identified"] == ["spring", "tyre", "bar"]
    true_bar = case.vehicle.known.anti_roll_bar_stiffness_N_per_m
    assert abs(stiffness["anti_roll_bar"] / true_bar - 1) < 0.10
    errors = identification_errors(case, result)
    assert errors["spring"] < 10 and errors["tyre"] < STIFFNESS_TOLERANCE_PERCENT
    assert errors["sprung mass"] < MASS_TOLERANCE_PERCENT
