"""A model with effect families identified on a recording: the paper's objective minimised exactly, channel
parameters by Gauss-Newton steps (finite-difference columns solved jointly with θ, within bounds). With
tyre_liftoff the airborne samples come from the fitted tyre force, decided again once.
"""

from __future__ import annotations

import numpy as np

from estimator.doctor.catalog import MAX_DELAY_S, EffectInstance, EffectName
from estimator.doctor.columns import with_columns
from estimator.doctor.model import FittedModel, ModelStructure, Reference, build_extended
from estimator.equations import LinearResiduals
from estimator.solvers.exact import solve_exact

GAUSS_NEWTON_ITERATIONS = 4
HALVINGS = 3
"""A Gauss-Newton step that raises the objective is halved at most this many times."""
GAUSS_NEWTON_STEP = {"delay": 5e-4, "lag": 5e-4, "average": 1e-3, "gain": 1e-3, "offset": 1e-4}
"""Finite-difference step of each kind of channel parameter (s, s, s, relative, m)."""
GAUSS_NEWTON_TOLERANCE = {"delay": 2e-6, "lag": 2e-6, "average": 4e-6, "gain": 1e-5, "offset": 1e-7}
NONNEGATIVE = frozenset({"delay", "lag", "average"})
"""Channel parameters that cannot be negative (a sensor lags, it does not lead), kept in [0, MAX_DELAY_S]."""


def feasible(kinds: list[str], values: np.ndarray) -> np.ndarray:
    """Channel parameter values moved into what a sensor can be: delays, lags and averaging windows in
    [0, MAX_DELAY_S], gain errors above −50%."""
    values = np.array(values, dtype=float)
    for j, kind in enumerate(kinds):
        if kind in NONNEGATIVE:
            values[j] = float(np.clip(values[j], 0.0, MAX_DELAY_S))
        elif kind == "gain":
            values[j] = max(values[j], -0.5)
    return values


def start_from(system: LinearResiduals, warm: FittedModel) -> np.ndarray:
    """θ of a similar model, matched by unknown name (new unknowns start at zero)."""
    return np.array([warm.value(name) for name in system.parameter_names])


def minimise(
    system: LinearResiduals, initial: np.ndarray | None, tolerance: float = 1e-10
) -> tuple[np.ndarray, float]:
    """θ minimising the paper's objective to `tolerance`, and the objective, as identify solves it."""
    solution = solve_exact(system, tolerance, initial=initial, certify=False)
    return solution.theta, solution.objective


def channel_jacobian(
    reference: Reference, model: FittedModel, which: list[int] | None = None
) -> dict[str, np.ndarray]:
    """Per Gauss-Newton parameter of the model (those at the indices `which`, when given), the change of
    its equation residual per unit of the parameter at the fitted θ, the airborne samples held: also what
    the Wald test of a channel family takes as the family's columns."""
    parameters = model.structure.channel_parameters
    base_residual = model.residuals()
    jacobian = {}
    for j, (effect, kind) in enumerate(parameters):
        if which is not None and j not in which:
            continue
        step, values = GAUSS_NEWTON_STEP[kind], np.array(model.channel_values, dtype=float)
        values[j] += step
        moved = build_extended(reference, model.structure, values, model.tyre, model.airborne or None)[0]
        jacobian[f"{kind} of {effect.label}"] = (moved.residuals(model.theta) - base_residual) / step
    return jacobian


def fit(reference: Reference, structure: ModelStructure, warm: FittedModel | None = None) -> FittedModel:
    """Identify `structure` on the reference recording, from `warm` (a fitted model of a similar structure,
    matched by unknown and by channel parameter; new ones start at zero). A Gauss-Newton step that raises
    the objective is halved, HALVINGS times at most before the fit keeps its best point (a delay and a lag
    of one channel are nearly collinear, and a full step clipped at zero can overshoot)."""
    parameters = structure.channel_parameters
    kinds = [kind for _, kind in parameters]
    values = warm.channel_values_for(parameters) if warm else np.zeros(len(parameters))
    liftoff = structure.has(EffectName.TYRE_LIFTOFF)
    vehicle, knots_m, tyre = reference.vehicle, reference.knots_m, (0.0, 0.0, 0.0)
    previous, best, step = warm, None, np.zeros(len(parameters))
    final_pass, steps, halvings = False, 0, 0
    while True:
        system, signals, airborne = build_extended(reference, structure, values, tyre)
        theta, objective = minimise(system, start_from(system, previous) if previous else None)
        model = FittedModel(
            structure, vehicle, theta, system, signals, values.copy(), airborne, objective, knots_m
        )
        if parameters and best is not None and objective > best.objective:
            if halvings == HALVINGS:
                return best
            halvings, step = halvings + 1, step / 2.0
            values = feasible(kinds, best.channel_values + step)
            continue
        best, previous, halvings = model, model, 0
        tyre = model.tyre
        if final_pass or (not parameters and not (liftoff and steps == 0)):
            return model
        steps += 1
        if not parameters:
            continue  # once more with the airborne samples of the fitted tyre force
        moved = bounded_step(system, theta, channel_jacobian(reference, model), kinds, values)
        step, values = moved - values, moved
        small = all(abs(d) < GAUSS_NEWTON_TOLERANCE[k] for d, k in zip(step, kinds, strict=True))
        affine = all(k == "offset" for k in kinds) and not liftoff
        final_pass = small or affine or steps == GAUSS_NEWTON_ITERATIONS


def bounded_step(
    used: LinearResiduals,
    theta: np.ndarray,
    jacobian: dict[str, np.ndarray],
    kinds: list[str],
    values: np.ndarray,
    free_solution: np.ndarray | None = None,
) -> np.ndarray:
    """The channel values after one Gauss-Newton step, θ solved with them, within the bounds of `feasible`
    (an active-set step): a parameter the step would push past its bound is held there and the others are
    solved again with its change in the offset (clipping afterwards would keep the others' share of a
    combined move). free_solution: the step with every parameter free (θ, then the steps), if solved."""
    names = list(jacobian)
    fixed: dict[int, float] = {}
    while True:
        free = [j for j in range(len(names)) if j not in fixed]
        offset = used.offset + sum((jacobian[names[j]] * change for j, change in fixed.items()), 0.0)
        if free_solution is not None and not fixed:
            solved = free_solution
        else:
            augmented = with_columns(used, {names[j]: jacobian[names[j]] for j in free}, offset)
            solved = minimise(augmented, np.concatenate([theta, np.zeros(len(free))]), 1e-8)[0]
        increment = np.zeros(len(names))
        increment[free] = solved[used.n_params :]
        for j, change in fixed.items():
            increment[j] = change
        moved = feasible(kinds, values + increment)
        clipped = [j for j in free if moved[j] != values[j] + increment[j]]
        if not clipped or len(free) == 1:
            return moved
        for j in clipped:
            fixed[j] = moved[j] - values[j]


def fit_added(
    reference: Reference, current: FittedModel, family: EffectInstance, start: FittedModel
) -> FittedModel:
    """The current model with `family` added, identified from `start` (its one-step model), or from the
    current model when that ends worse than the current model (a larger model cannot fit worse; one step
    of nearly collinear channel parameters can start far off)."""
    structure = current.structure.with_effect(family)
    model = fit(reference, structure, warm=start)
    return model if model.objective <= current.objective else fit(reference, structure, warm=current)
