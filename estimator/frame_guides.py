"""A laboratory quarter-car rig's frame guides (VehicleParameters.frame_guides): its body and its wheel ride
on guides fixed to a frame, and each rubs on its own guide, a Coulomb friction against that mass's own
velocity (estimator.dynamics.CornerPhysics spells the force out; a vehicle on a plate has none). On a rig of
a few kg it is most of the damping: identify fits it where the vehicle file states the guides, the model
file carries it (estimator.model_io's effects), and the model doctor tests it as a family.

Here: the two unknowns' names, which are the model file's effect keys, and their columns in the equations
of motion (estimator.equations' f1, f2)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from estimator.friction import coulomb_sign, interval_mean

GUIDE_FRICTION_NAMES = ("guide_body_friction_N", "guide_wheel_friction_N")
"""The body's and the wheel's friction against the frame (N): unknowns of the equations, effect keys of the
model file."""
GUIDED_MASSES = ("body", "wheel")
"""The mass each of GUIDE_FRICTION_NAMES acts on, in their order (what a report calls them)."""


def guide_columns(
    body_velocity_m_s: np.ndarray,
    wheel_velocity_m_s: np.ndarray,
    equation_filter: Callable[[np.ndarray], np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """The (body, wheel) frictions' columns, shape (2 equations, samples) each: each mass's friction per
    newton in its own equation (+ in the residual, as the force opposes that mass's velocity), the smoothed
    sign's mean over each sample interval (a step at a zero crossing acts for its share of the interval),
    passed through `equation_filter` (the equations' low-pass and sample selection)."""
    body, wheel = (
        equation_filter(interval_mean(coulomb_sign, v)) for v in (body_velocity_m_s, wheel_velocity_m_s)
    )
    zero = np.zeros_like(body)
    return np.stack([body, zero]), np.stack([zero, wheel])
