"""A laboratory rig's frame guides (estimator.dynamics.CornerPhysics: friction of the body and of the wheel
against the frame) in the compiled simulation kernel, built ahead of time and just in time (the fixtures of
test_simulation_kernel), against the reference dynamics, on the models of test_simulation_kernel."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_simulation_kernel import (  # kernel: each test with the extension, then with numba's kernel
    _axle,
    _both,
    _quarter_car,
    _quarter_car_drive,
    assert_same_trajectories,
    extension_kernel,  # noqa: F401 (the fixture `kernel` uses)
    kernel,  # noqa: F401 (autouse)
)

from estimator.vehicle import TyreModel


def test_quarter_car_population_with_frame_guide_friction() -> None:
    """A lab rig's frame guides (friction of the body and of the wheel against the frame, in some columns
    and not in others, beside the other effects): the compiled kernel follows the reference, the guides
    change the motion only where a column has them, and an axle refuses them."""
    columns = 6
    base = _quarter_car(12, columns, TyreModel.MAXWELL, effects=True)
    rng = np.random.default_rng(612)
    guided = np.array([True, True, False, True, False, True])
    body = np.where(guided, rng.uniform(20.0, 200.0, columns), 0.0)
    wheel = np.where(guided & (rng.random(columns) < 0.7), rng.uniform(20.0, 200.0, columns), 0.0)
    physics = replace(
        base, corner=replace(base.corner, guide_body_friction_N=body, guide_wheel_friction_N=wheel)
    )
    plate, rate, state0 = _quarter_car_drive(612, columns)
    reference, compiled = _both(physics, state0, plate, rate)
    assert np.all(np.isfinite(reference))
    assert_same_trajectories(reference, compiled)
    plain, _ = _both(base, state0, plate, rate)
    moved = np.max(np.abs(plain[:, 0] - reference[:, 0]), axis=0)
    print(f"body motion changed by the guides: {moved * 1e6} µm")
    assert np.all(moved[guided] > 1e-6) and np.all(moved[~guided] == 0.0)
    with pytest.raises(ValueError, match="frame guides"):
        axle = _axle(21, 2)
        replace(axle, left=replace(axle.left, guide_body_friction_N=10.0))
