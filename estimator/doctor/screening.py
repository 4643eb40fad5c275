"""A candidate family tested by one linearised step from the current model instead of a full fit: from a
consistent estimate one step is as efficient as the fit (Le Cam's one-step estimator), so the Wald statistic
of its unknowns is the family's score test. Only the family a round names is fitted fully.
"""

from __future__ import annotations

import numpy as np

from estimator.doctor.catalog import EffectInstance
from estimator.doctor.columns import with_columns
from estimator.doctor.criteria import EquationTest, TestResult
from estimator.doctor.fitting import bounded_step, channel_jacobian, feasible, minimise, start_from
from estimator.doctor.model import FittedModel, Reference, build_extended


def one_step(
    reference: Reference, current: FittedModel, candidate: EffectInstance
) -> tuple[FittedModel, TestResult]:
    """The current model with `candidate` added and its unknowns moved by one linearised step, and the Wald
    test of those unknowns (their channel parameters' steps included) against zero."""
    structure = current.structure.with_effect(candidate)
    parameters = structure.channel_parameters
    vehicle, knots_m = reference.vehicle, reference.knots_m
    values = current.channel_values_for(parameters)
    system, signals, airborne = build_extended(reference, structure, values, current.tyre)
    start = start_from(system, current)
    own = [k for k, (effect, _) in enumerate(parameters) if effect == candidate]
    model = FittedModel(
        structure, vehicle, start, system, signals, values, airborne, current.objective, knots_m
    )
    jacobian = channel_jacobian(reference, model, which=own)
    augmented = with_columns(system, jacobian, system.offset) if jacobian else system
    solution, objective = minimise(augmented, np.concatenate([start, np.zeros(len(jacobian))]))
    theta, steps = solution[: system.n_params], solution[system.n_params :]
    own_kinds = [parameters[k][1] for k in own]
    if np.any(feasible(own_kinds, values[own] + steps) != values[own] + steps):
        # the test keeps the unbounded step; the model moves by the step within the bounds
        values[own] = bounded_step(system, start, jacobian, own_kinds, values[own], solution)
        system, signals, airborne = build_extended(reference, structure, values, current.tyre)
        theta, objective = minimise(system, start)
    else:
        values[own] = values[own] + steps
    added = [n for n in system.parameter_names if n not in current.system.parameter_names]
    index = [system.parameter_names.index(n) for n in added] + list(
        range(system.n_params, system.n_params + len(own))
    )
    test = EquationTest().test_at(augmented, solution, index, reference.recording.sample_time_s)
    stepped = FittedModel(structure, vehicle, theta, system, signals, values, airborne, objective, knots_m)
    return stepped, test
