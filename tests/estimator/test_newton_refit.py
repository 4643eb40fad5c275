"""Newton re-solves (estimator.newton_refit) reach the optimum the IRLS solvers reach, from a nearby start:
the confidence bands' bias allowances and the end of the ϑ search rely on it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from estimator import relaxation
from estimator.equations import build
from estimator.newton_refit import newton_refit
from estimator.relaxation import RELAXATION_TIME_BOUNDS_S
from estimator.solvers.exact import solve_exact
from estimator.sweep import SweepSettings
from estimator.uncertainty import Z_95, confidence_intervals
from estimator.vehicle import TyreModel, VehicleConstant, coefficient_from_relaxation_time
from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate


@pytest.fixture(scope="module")
def recording_and_vehicle():
    car = default_quarter_car()
    recording = simulate(car, SimulationSettings(sweep=SweepSettings(duration_s=6.0), seed=5)).recording
    return recording, car.known


def test_from_a_nearby_start_newton_reaches_the_exact_optimum(recording_and_vehicle) -> None:
    """A lower kinematics cutoff moves the optimum a little (as the bands' filter allowance does): Newton from
    the old optimum reaches the new one IRLS finds from scratch, to a GF no higher."""
    recording, vehicle = recording_and_vehicle
    system = build(recording, vehicle, TyreModel.MAXWELL)
    start = solve_exact(system, certify=False).theta
    lower = replace(system.filters, kinematics_cutoff_Hz=0.8 * system.filters.kinematics_cutoff_Hz)
    moved = build(recording, vehicle, TyreModel.MAXWELL, filters=lower, grids=system.grids_m_s)
    exact = solve_exact(moved, tolerance=1e-12, certify=False)
    refit = newton_refit(moved, start)
    assert refit.relaxation_time_s is None
    assert refit.objective <= exact.objective * (1 + 1e-9)
    # the same optimum: apart by a hundredth of the noise-driven 95% half-width at most (GF is flat to
    # 1e-14 along the poorly determined tyre damping, where two solvers stop at slightly different points)
    half_width = Z_95 * confidence_intervals(moved, exact.theta, recording.sample_time_s).standard_error
    assert np.all(np.abs(refit.theta - exact.theta) <= 0.01 * half_width)
    # and it did have to move: 10 times that tolerance at least (the filter allowance's size)
    assert np.max(np.abs(exact.theta - start) / half_width) > 0.1


def test_with_the_relaxation_time_free_newton_reaches_the_joint_optimum(
    recording_and_vehicle, monkeypatch: pytest.MonkeyPatch
) -> None:
    """ϑ free (log τ one more unknown): from the optimum at a τ 10% off, Newton finds the τ and GF of the
    joint search by IRLS alone run to a tight tolerance (no hand-over to Newton), within the bounds; and
    fit_relaxation_time as it runs (IRLS handing over to Newton) ends there too, certified."""
    recording, vehicle = recording_and_vehicle
    unknown = frozenset({VehicleConstant.SPRING, VehicleConstant.TYRE})
    system = build(recording, vehicle, TyreModel.MAXWELL, free=unknown)
    with monkeypatch.context() as patch:
        patch.setattr(relaxation, "NEWTON_HANDOVER", 0.0)
        irls = relaxation.fit_relaxation_time(system, tolerance=1e-11)
    off = system.with_tyre_theta(_theta_at(1.1 * irls.relaxation_time_s, recording.sample_time_s))
    refit = newton_refit(off, solve_exact(off, certify=False).theta, RELAXATION_TIME_BOUNDS_S)
    assert refit.relaxation_time_s == pytest.approx(irls.relaxation_time_s, rel=1e-4)
    assert refit.objective <= irls.solution.objective * (1 + 1e-9)
    hybrid = relaxation.fit_relaxation_time(system)
    assert hybrid.relaxation_time_s == pytest.approx(irls.relaxation_time_s, rel=1e-4)
    assert hybrid.solution.objective <= irls.solution.objective * (1 + 1e-9)
    assert hybrid.solution.certified_gap < 1e-6


def _theta_at(relaxation_time_s: float, sample_time_s: float) -> float:
    return coefficient_from_relaxation_time(relaxation_time_s, sample_time_s)


def test_exact_solver_handing_over_to_newton_reaches_the_irls_optimum(
    recording_and_vehicle, monkeypatch: pytest.MonkeyPatch
) -> None:
    """solve_exact's IRLS hands over to Newton steps: the same optimum as IRLS alone run to its tolerance
    (a GF no higher, the same θ within a part in 10⁵ of each unknown's spread), certified, in fewer
    weighted normal matrices."""
    recording, vehicle = recording_and_vehicle
    system = build(recording, vehicle, TyreModel.MAXWELL, free=frozenset({VehicleConstant.SPRING}))
    from estimator.solvers import exact

    with monkeypatch.context() as patch:
        patch.setattr(exact, "NEWTON_HANDOVER", 0.0)
        irls = solve_exact(system)
    hybrid = solve_exact(system)
    assert hybrid.objective <= irls.objective * (1 + 1e-12)
    assert hybrid.certified_gap < 1e-6
    spread = np.maximum(np.abs(irls.theta), 1e-9 * np.max(np.abs(irls.theta)))
    assert np.max(np.abs(hybrid.theta - irls.theta) / spread) < 1e-5
    assert hybrid.iterations < irls.iterations
