"""estimator.equations.damper_grids: the filters and damper velocity grids `build` chooses, without the system
(the model doctor asks for them once per bootstrap draw). They must be build's exactly, for a quarter car and
for both sides of an axle, at the default number of points and at one asked for."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.equations import build, damper_grids
from estimator.sweep import SweepSettings
from estimator.vehicle import TyreModel
from simulators.vehicle_sim import SimulationSettings, default_axle, default_quarter_car, simulate


@pytest.mark.parametrize("make", [default_quarter_car, default_axle], ids=["quarter car", "axle"])
@pytest.mark.parametrize("points", [None, 27])
def test_damper_grids_are_builds_own(make, points: int | None) -> None:
    vehicle = make()
    for seed in (1, 2):
        settings = SimulationSettings(sweep=SweepSettings(duration_s=3.0), seed=seed)
        recording = simulate(vehicle, settings).recording
        system = build(recording, vehicle.known, TyreModel.SPRING, points, 2000)
        filters, grids = damper_grids(recording, vehicle.known, points, 2000)
        assert filters == system.filters
        assert len(grids) == len(system.grids_m_s) == (2 if vehicle.known.is_axle else 1)
        for grid, built in zip(grids, system.grids_m_s, strict=True):
            np.testing.assert_array_equal(grid, built)
