"""Randomly drawn simulated vehicles (fixed seeds) with a real damper table that is not of the tanh form, and
what an identification got wrong about them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cache

import numpy as np

from estimator.dynamics import ForceCurve
from estimator.identify import IdentificationResult
from estimator.sweep import SweepSettings
from estimator.vehicle import (
    REFERENCE_SAMPLE_TIME_S,
    ModelKind,
    VehicleParameters,
    coefficient_from_relaxation_time,
)
from simulators.dampers import suv_rear_table
from simulators.vehicle_sim import (
    SimulatedVehicle,
    SimulationResult,
    SimulationSettings,
    simulate,
    true_damper,
)

SWEEP_S = 15.0
NOISE_M = 5e-6


@dataclass(frozen=True)
class Case:
    name: str
    vehicle: SimulatedVehicle
    result: SimulationResult

    @property
    def truths(self) -> list[ForceCurve]:
        return [true_damper(d) for d in self.vehicle.dampers]


def random_quarter_car(seed: int) -> SimulatedVehicle:
    rng = np.random.default_rng(seed)
    mass = rng.uniform(320, 520)
    known = VehicleParameters(
        ModelKind.QUARTER_CAR,
        mass,
        rng.uniform(18e3, 35e3),
        rng.uniform(180e3, 260e3),
        rng.uniform(0.95, 0.98),
    )
    return SimulatedVehicle(
        known,
        rng.uniform(0.85, 0.92) * mass,
        (suv_rear_table(rng.uniform(0.6, 1.1)),),
        tyre_damping_Ns_per_m=rng.uniform(800, 2000),
    )


def random_axle(seed: int) -> SimulatedVehicle:
    """An axle with an anti-roll bar and different left and right dampers."""
    rng = np.random.default_rng(seed)
    mass = rng.uniform(700, 1000)
    known = VehicleParameters(
        ModelKind.AXLE,
        mass,
        rng.uniform(18e3, 35e3),
        rng.uniform(180e3, 260e3),
        rng.uniform(0.95, 0.98),
        track_m=rng.uniform(1.4, 1.6),
        anti_roll_bar_stiffness_N_per_m=rng.uniform(8e3, 25e3),
    )
    dampers = (suv_rear_table(rng.uniform(0.8, 1.1)), suv_rear_table(rng.uniform(0.5, 0.75)))
    return SimulatedVehicle(
        known,
        rng.uniform(0.85, 0.92) * mass,
        dampers,
        tyre_damping_Ns_per_m=rng.uniform(800, 2000),
        roll_inertia_kg_m2=rng.uniform(200, 400),
    )


@cache
def quarter_car_case(seed: int) -> Case:
    vehicle = random_quarter_car(seed)
    settings = SimulationSettings(sweep=SweepSettings(duration_s=SWEEP_S), seed=seed)
    return Case(f"quarter car seed {seed}", vehicle, simulate(vehicle, settings))


@cache
def axle_case(seed: int) -> Case:
    vehicle = random_axle(seed)
    settings = SimulationSettings(sweep=SweepSettings(duration_s=SWEEP_S), seed=seed)
    return Case(f"axle seed {seed}", vehicle, simulate(vehicle, settings))


@dataclass(frozen=True)
class PointwiseForce:
    """A force law of one velocity at a time (a simulator's damper: force_at(v) in N, v in m/s) as a
    ForceCurve over an array, for curve_error_percent's truth."""

    force_at: Callable[[float], float]

    def force(self, velocity_m_s: np.ndarray) -> np.ndarray:
        return np.array([self.force_at(float(v)) for v in velocity_m_s])


def curve_error_percent(identified: ForceCurve, truth: ForceCurve, velocity_m_s: np.ndarray) -> float:
    """RMS of identified − true force over the excited velocity range (0.5%..99.5% quantiles of the measured
    suspension velocity), in % of the true curve's peak |force| there."""
    lo, hi = np.quantile(velocity_m_s, [0.005, 0.995])
    grid = np.linspace(lo, hi, 400)
    true = truth.force(grid)
    return float(100 * np.sqrt(np.mean((identified.force(grid) - true) ** 2)) / np.max(np.abs(true)))


def mass_only(known: VehicleParameters) -> VehicleParameters:
    """The vehicle file with only the mass (and an axle's track and bar): the rest is to be identified."""
    return replace(
        known, spring_stiffness_N_per_m=None, tyre_stiffness_N_per_m=None, tyre_viscoelastic_coefficient=None
    )


def random_wide_quarter_car(seed: int) -> SimulatedVehicle:
    """A quarter car drawn over a wider range than random_quarter_car, for identification from the mass
    alone: mass, sprung share, spring, tyre stiffness, tyre damping and relaxation time, and the real
    SUV damper table scaled."""
    rng = np.random.default_rng(seed)
    mass = rng.uniform(250, 600)
    known = VehicleParameters(
        ModelKind.QUARTER_CAR,
        mass,
        rng.uniform(15e3, 60e3),
        rng.uniform(150e3, 350e3),
        coefficient_from_relaxation_time(rng.uniform(0.015, 0.05), REFERENCE_SAMPLE_TIME_S),
    )
    return SimulatedVehicle(
        known,
        rng.uniform(0.82, 0.93) * mass,
        (suv_rear_table(rng.uniform(0.5, 1.2)),),
        tyre_damping_Ns_per_m=rng.uniform(600, 2000),
    )


@cache
def wide_quarter_car_case(seed: int, sample_time_s: float = 0.001) -> Case:
    vehicle = random_wide_quarter_car(seed)
    settings = SimulationSettings(
        sweep=SweepSettings(duration_s=SWEEP_S), seed=seed, sample_time_s=sample_time_s
    )
    rate = f"{1 / sample_time_s:.0f} Hz"
    return Case(f"quarter car seed {seed} at {rate}", vehicle, simulate(vehicle, settings))


@cache
def axle_case_at(seed: int, sample_time_s: float) -> Case:
    vehicle = random_axle(seed)
    settings = SimulationSettings(
        sweep=SweepSettings(duration_s=SWEEP_S), seed=seed, sample_time_s=sample_time_s
    )
    return Case(f"axle seed {seed} at {1 / sample_time_s:.0f} Hz", vehicle, simulate(vehicle, settings))


def identification_errors(case: Case, result: IdentificationResult) -> dict[str, float]:
    """|error| in % of what the identification found: each curve (of its peak force, curve_error_percent),
    sprung and unsprung mass, spring and tyre stiffness, the tyre's relaxation time (when identified)."""
    truth, found = case.vehicle, result.model
    errors = {
        f"curve {c.corner}": curve_error_percent(c.curve, t, v)
        for c, t, v in zip(result.curves, case.truths, result.system.velocity_m_s, strict=True)
    }
    pairs = {
        "sprung mass": (found.sprung_mass_kg, truth.sprung_mass_kg),
        "unsprung mass": (found.unsprung_mass_kg, truth.unsprung_mass_kg),
        "spring": (found.vehicle.spring_stiffness_N_per_m, truth.known.spring_stiffness_N_per_m),
        "tyre": (found.vehicle.tyre_stiffness_N_per_m, truth.known.tyre_stiffness_N_per_m),
        "relaxation time": (found.vehicle.tyre_relaxation_time_s, truth.known.tyre_relaxation_time_s),
    }
    # a tyre model without ϑ identifies no relaxation time
    errors |= {name: 100 * abs(a / b - 1) for name, (a, b) in pairs.items() if a is not None}
    return errors
