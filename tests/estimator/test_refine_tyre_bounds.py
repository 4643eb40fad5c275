"""Refinement on the output error with a negative equation-error tyre damping (a Kelvin-Voigt tyre on noisy
data gives one): the search used to get bounds [0, negative] and fail with "bounds must have shape (p, 2)
with low < high" (issue 14: tyre=kelvin-voigt with refine=true always failed)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from estimator.equations import build
from estimator.identify import IdentifyOptions, identify
from estimator.output_error import refine_on_output_error
from estimator.solvers.differential_evolution import DESettings
from estimator.sweep import SweepSettings
from estimator.vehicle import TyreModel
from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate


def test_a_negative_tyre_damping_refines_from_zero_within_ordered_bounds() -> None:
    vehicle = default_quarter_car()
    recording = simulate(vehicle, SimulationSettings(sweep=SweepSettings(duration_s=4.0), seed=2)).recording
    options = IdentifyOptions(tyre=TyreModel.KELVIN_VOIGT, output_error=False)
    identified = identify(recording, vehicle.known, options).model
    negative = replace(identified, tyre_damping_Ns_per_m=-136.0)
    system = build(recording, vehicle.known, TyreModel.KELVIN_VOIGT, None, options.nsample)
    refined, gap = refine_on_output_error(
        negative,
        recording,
        system.kinematics,
        system.filters.noise_floor_m,
        settings=DESettings(generations=3, population_size=8, seed=1),
    )
    assert 0.0 <= refined.tyre_damping_Ns_per_m <= 50.0  # searched in [0, 50] from 0, not refused
    assert np.isfinite(gap)
