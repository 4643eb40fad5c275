"""Must show (issue 13, item 5, third bullet): once tyre_liftoff is named, the doctor's gap comes close to
what a complete model leaves, on recordings of the independent world (simulators/independent), which simulates
lift-off physically: the contact force max(0, ...) and the tyre's Maxwell element relaxing off the plate.

- the Maxwell element is not driven while the tyre is off the plate (estimator.dynamics), in the kernel as in
  the Python reference (their equality is tests/estimator/test_simulation_kernel.py);
- the fitted lift-off model's tyre leaves the plate where the independent world's does;
- a lift-off recording: tyre_liftoff named and the gap within 2x the expected gap of a complete model and
  under 200 µm (before the element relaxed off the plate: 389 µm on the van below, 43 µm after).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from independent_recordings import recorded

from estimator.damper import PiecewiseLinearCurve
from estimator.doctor import DiagnoseOptions, diagnose
from estimator.doctor.catalog import EffectInstance, EffectName
from estimator.doctor.fitting import fit
from estimator.doctor.model import FitSettings, Reference, starting_structure
from estimator.dynamics import CornerPhysics
from estimator.recording import Recording
from estimator.vehicle import TyreModel, VehicleParameters
from simulators.independent.cases import Case
from simulators.independent.world import WorldRecording

SWEEP_S = 10.0
LIFTOFF_SEEDS = (1,)
MAX_GAP_OVER_EXPECTED = 2.0
MAX_GAP_M = 200e-6
"""Besides: what clean recordings of the independent world leave is 20-100 µm; the expected gap alone is not
enough, since it is simulated by the doctor's own lift-off model (with the element driven through the
flight it came out at 2647 µm on the van, and 389 µm passed as 0.15x)."""


def _world(seed: int, folder: Path) -> tuple[Case, WorldRecording, Recording, VehicleParameters]:
    return recorded("tyre_liftoff", seed, folder, SWEEP_S)


def test_off_the_plate_the_maxwell_element_relaxes() -> None:
    corner = CornerPhysics(
        damper=PiecewiseLinearCurve(np.array([-1.0, 1.0]), np.array([-1000.0, 1000.0])),
        spring_stiffness_N_per_m=30e3,
        tyre_stiffness_N_per_m=200e3,
        tyre_damping_Ns_per_m=400.0,
        maxwell_time_constant_s=0.02,
        tyre_liftoff=np.array([True, False]),
        static_wheel_load_N=3000.0,
    )
    deflection = np.array([0.02, 0.02])  # 4000 N of pull: off the plate where lift-off is modelled
    rate, maxwell = np.array([0.5, 0.5]), np.array([50.0, 50.0])
    tyre = corner.tyre_force_N(deflection, rate, maxwell)
    assert tyre[0] == -3000.0 and tyre[1] < -3000.0
    relaxing, driven = corner.maxwell_rate(rate, maxwell, tyre)
    assert relaxing == -50.0 / 0.02
    assert driven == (400.0 * 0.5 - 50.0) / 0.02
    in_contact = corner.tyre_force_N(np.zeros(2), rate, maxwell)
    assert np.all(corner.maxwell_rate(rate, maxwell, in_contact) == (400.0 * 0.5 - 50.0) / 0.02)


def test_the_fitted_tyre_leaves_the_plate_where_the_world_s_does(tmp_path: Path) -> None:
    for seed in LIFTOFF_SEEDS:
        _, world, recording, vehicle = _world(seed, tmp_path)
        reference = Reference.of(recording, vehicle, FitSettings())
        structure = starting_structure(TyreModel.MAXWELL).with_effect(EffectInstance(EffectName.TYRE_LIFTOFF))
        model = fit(reference, structure)
        airborne = model.airborne[0] > 0.5
        truth = world.contact_N[0] <= 0.0
        assert truth.mean() > 0.01
        disagree = float(np.mean(airborne != truth))
        assert disagree <= 0.05 * truth.mean(), f"seed {seed}: {disagree:.4%} of samples disagree"


def test_a_named_liftoff_brings_the_gap_near_a_complete_model_s(hit_rate, tmp_path: Path) -> None:
    hits = []
    for seed in LIFTOFF_SEEDS:
        case, _, recording, vehicle = _world(seed, tmp_path)
        result = diagnose(recording, vehicle, DiagnoseOptions(tyre=TyreModel.MAXWELL))
        ratio = result.gap_after_m / result.expected_gap_m
        hit = (
            "tyre_liftoff" in result.effects_named
            and ratio <= MAX_GAP_OVER_EXPECTED
            and result.gap_after_m <= MAX_GAP_M
        )
        hits.append(hit)
        hit_rate(
            "independent world, lift-off: named, gap within 2x a complete model's",
            f"{case.description}: named {result.effects_named}, gap {result.gap_before_m * 1e6:.1f} -> "
            f"{result.gap_after_m * 1e6:.1f} µm (expected {result.expected_gap_m * 1e6:.1f} µm, "
            f"{ratio:.2f}x)",
            hit,
        )
    assert all(hits), f"{sum(hits)}/{len(hits)}"
