"""Randomly drawn simulated vehicles (fixed seeds) with a real damper table that is not of the tanh form."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from drivers.exciter.sweep import SweepSettings
from estimator.dynamics import ForceCurve
from estimator.vehicle import ModelKind, VehicleParameters
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


def curve_error_percent(identified: ForceCurve, truth: ForceCurve, velocity_m_s: np.ndarray) -> float:
    """RMS of identified − true force over the excited velocity range (0.5%..99.5% quantiles of the measured
    suspension velocity), in % of the true curve's peak |force| there."""
    lo, hi = np.quantile(velocity_m_s, [0.005, 0.995])
    grid = np.linspace(lo, hi, 400)
    true = truth.force(grid)
    return float(100 * np.sqrt(np.mean((identified.force(grid) - true) ** 2)) / np.max(np.abs(true)))
