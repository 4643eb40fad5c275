"""A candidate family tested by one linearised step from the current model, instead of a full fit.

A round asks of every family the model lacks whether its unknowns are zero. The full fit of each (Gauss-Newton
iterations for a channel family, each a build of the equations) is the costly part of a round; a one-step
estimator is not: at the current model's θ, with the family's unknowns at zero, the family's force columns
(estimator.doctor.catalog) and the residual's derivatives by its channel parameters (finite differences, one
build each) are appended, and the linearised system is minimised once. Starting from a consistent estimate,
one such step is asymptotically as efficient as the full fit (the one-step estimator of Le Cam), so the Wald
statistic of the step's unknowns is the score test of the family at the current model. Only the family a
round names is then fitted fully (estimator.doctor.fitting.fit).
"""

from __future__ import annotations

import numpy as np

from estimator.doctor.catalog import EffectInstance
from estimator.doctor.columns import with_columns
from estimator.doctor.criteria import EquationTest, TestResult
from estimator.doctor.fitting import bounded_step, channel_jacobian, feasible, minimise, start_from
from estimator.doctor.model import FittedModel, Reference, build_at


def one_step(
    reference: Reference, current: FittedModel, candidate: EffectInstance
) -> tuple[FittedModel, TestResult]:
    """The current model with `candidate` added and its unknowns moved by one linearised step, and the Wald
    test of those unknowns (their channel parameters' steps included) against zero."""
    structure = current.structure.with_effect(candidate)
    parameters = structure.channel_parameters
    previous = dict(zip(current.structure.channel_parameters, current.channel_values, strict=True))
    values = np.array([previous.get(p, 0.0) for p in parameters], dtype=float)
    system, signals, airborne = build_at(reference, current, structure, values)
    start = start_from(system, current)
    own = [k for k, (effect, _) in enumerate(parameters) if effect == candidate]
    model = FittedModel(
        structure,
        reference.vehicle,
        start,
        system,
        signals,
        values,
        airborne,
        current.objective,
        reference.knots_m,
    )
    jacobian = channel_jacobian(reference, model, which=own)
    augmented = with_columns(system, jacobian, system.offset) if jacobian else system
    solution, objective = minimise(augmented, np.concatenate([start, np.zeros(len(jacobian))]))
    theta, steps = solution[: system.n_params], solution[system.n_params :]
    kinds = [kind for _, kind in parameters]
    own_kinds = [kinds[k] for k in own]
    if np.any(feasible(own_kinds, values[own] + steps) != values[own] + steps):
        # the test keeps the unbounded step; the model moves by the step within the bounds
        values[own] = bounded_step(system, start, jacobian, own_kinds, values[own], solution)
        system, signals, airborne = build_at(reference, current, structure, values)
        theta, objective = minimise(system, start)
    else:
        values[own] = values[own] + steps
    added = [n for n in system.parameter_names if n not in current.system.parameter_names]
    index = [system.parameter_names.index(n) for n in added] + list(
        range(system.n_params, system.n_params + len(own))
    )
    test = EquationTest().test_at(augmented, solution, index, reference.recording.sample_time_s)
    stepped = FittedModel(
        structure, reference.vehicle, theta, system, signals, values, airborne, objective, reference.knots_m
    )
    return stepped, test
