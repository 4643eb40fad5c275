"""How a model with effect families is identified (fit) on a recording (estimator.doctor.model builds its
equations): the paper's objective is minimised exactly (estimator.solvers.exact). Channel parameters (a
sensor's delay, lag, averaging window, gain error, offset) are found by Gauss-Newton steps: the residual's
change per unit of each parameter is taken by finite differences at the current solution (channel_jacobian),
appended as columns and solved jointly with θ, within the parameters' bounds (bounded_step), repeated. With
tyre_liftoff the airborne samples come from the fitted tyre force and are re-determined once.
"""

from __future__ import annotations

import numpy as np

from estimator.doctor.catalog import MAX_DELAY_S, EffectInstance, EffectName
from estimator.doctor.columns import restrict, with_columns
from estimator.doctor.model import (
    FittedModel,
    ModelStructure,
    Reference,
    build_extended,
    corrections_of,
    tyre_coefficients,
)
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
    known = dict(zip(warm.system.parameter_names, warm.theta, strict=True))
    return np.array([known.get(name, 0.0) for name in system.parameter_names])


def minimise(
    system: LinearResiduals, initial: np.ndarray | None, tolerance: float = 1e-10
) -> tuple[np.ndarray, float]:
    """θ minimising the paper's objective, and the objective: estimator.solvers.exact's IRLS handing over to
    Newton steps, to `tolerance`, as identify does."""
    solution = solve_exact(system, tolerance, initial=initial, certify=False)
    return solution.theta, solution.objective


def channel_jacobian(
    reference: Reference,
    model: FittedModel,
    rows: np.ndarray | None = None,
    which: list[int] | None = None,
) -> dict[str, np.ndarray]:
    """Per Gauss-Newton parameter of the model (those at the indices `which`, when given), the change of its
    equation residual per unit of the parameter at the fitted θ (finite differences of GAUSS_NEWTON_STEP; the
    airborne samples held), restricted to `rows` when given. Also what the Wald test of a channel family
    treats as the family's columns."""
    parameters = model.structure.channel_parameters
    tyre = tyre_coefficients(model.system, model.theta)
    airborne = model.airborne or None
    base = restrict(model.system, rows) if rows is not None else model.system
    base_residual = base.residuals(model.theta)
    jacobian = {}
    for j, (effect, kind) in enumerate(parameters):
        if which is not None and j not in which:
            continue
        values = np.array(model.channel_values, dtype=float)
        values[j] += GAUSS_NEWTON_STEP[kind]
        moved, _, _ = build_extended(
            reference, model.structure, corrections_of(parameters, values), airborne, tyre
        )
        moved = restrict(moved, rows) if rows is not None else moved
        jacobian[f"{kind} of {effect.label}"] = (
            moved.residuals(model.theta) - base_residual
        ) / GAUSS_NEWTON_STEP[kind]
    return jacobian


def fit(
    reference: Reference,
    structure: ModelStructure,
    rows: np.ndarray | None = None,
    warm: FittedModel | None = None,
    iterations: int = GAUSS_NEWTON_ITERATIONS,
) -> FittedModel:
    """Identify `structure` on the reference recording, using only the selected samples where `rows` is
    True (all when None). warm: a fitted model of a similar structure to start from (its unknowns and
    channel parameters, matched by family and kind; new ones start at zero). iterations: Gauss-Newton steps
    at most (channel families). A step that raises the objective is halved (at most HALVINGS times, then
    the fit keeps its best point): a delay and a lag of one channel are nearly collinear, and a full step
    clipped at zero can overshoot."""
    parameters = structure.channel_parameters
    kinds = [kind for _, kind in parameters]
    start = dict(zip(warm.structure.channel_parameters, warm.channel_values, strict=True)) if warm else {}
    values = np.array([start.get(p, 0.0) for p in parameters], dtype=float)
    liftoff = structure.has(EffectName.TYRE_LIFTOFF)
    tyre = (0.0, 0.0, 0.0)
    previous, best, step = warm, None, np.zeros(len(parameters))
    final_pass, steps, halvings = False, 0, 0
    while True:
        system, signals, airborne = build_extended(
            reference, structure, corrections_of(parameters, values), None, tyre
        )
        used = restrict(system, rows) if rows is not None else system
        theta, objective = minimise(used, start_from(used, previous) if previous else None)
        model = FittedModel(
            structure,
            reference.vehicle,
            theta,
            system,
            signals,
            values.copy(),
            airborne if liftoff else [],
            objective,
            reference.knots_m,
        )
        if parameters and best is not None and objective > best.objective:
            if halvings == HALVINGS:
                return best
            halvings, step = halvings + 1, step / 2.0
            values = feasible(kinds, best.channel_values + step)
            continue
        best, previous, halvings = model, model, 0
        tyre = tyre_coefficients(system, theta)
        if final_pass or (not parameters and not (liftoff and steps == 0)):
            return model
        steps += 1
        if not parameters:
            continue  # once more with the airborne samples of the fitted tyre force
        moved = bounded_step(used, theta, channel_jacobian(reference, model, rows), kinds, values)
        step, values = moved - values, moved
        small = all(abs(d) < GAUSS_NEWTON_TOLERANCE[k] for d, k in zip(step, kinds, strict=True))
        affine = all(k == "offset" for k in kinds) and not liftoff
        final_pass = small or affine or steps == iterations


def bounded_step(
    used: LinearResiduals,
    theta: np.ndarray,
    jacobian: dict[str, np.ndarray],
    kinds: list[str],
    values: np.ndarray,
    free_solution: np.ndarray | None = None,
) -> np.ndarray:
    """The channel values after one Gauss-Newton step, θ solved with them, under the bounds of `feasible`
    (an active-set step): a parameter the step would push past its bound is held at the bound and the
    others are solved again with its change in the offset. Clipping afterwards instead would keep the
    others' share of a combined move: a delay and an averaging window of one channel fitted to a pure
    3 ms delay step to +10 ms and −7 ms, and clipping the window at zero left the delay at 10 ms.
    free_solution: the step with every parameter free, when the caller has solved it (θ, then the
    parameters' steps), so that it is not solved again."""
    names = list(jacobian)
    fixed: dict[int, float] = {}
    while True:
        free = [j for j in range(len(names)) if j not in fixed]
        offset = used.offset + sum((jacobian[names[j]] * change for j, change in fixed.items()), 0.0)
        if free_solution is not None and not fixed:  # the unbounded step, solved already by the caller
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
    current model when that ends worse than the current model: a larger model cannot fit worse, and a
    one step of nearly collinear channel parameters (a delay and a lag) can start far off."""
    structure = current.structure.with_effect(family)
    model = fit(reference, structure, warm=start)
    return model if model.objective <= current.objective else fit(reference, structure, warm=current)
