"""A model with effect families identified on a recording (fit): the paper's objective minimised exactly,
channel parameters by Gauss-Newton steps (finite-difference columns solved jointly with θ, within bounds);
with tyre_liftoff the airborne samples come from the fitted tyre force, decided again once.

A candidate is screened by one linearised step from the current model (one_step): from a consistent estimate
one step is as efficient as the fit (Le Cam), so the Wald statistic of its unknowns is a score test. Only the
family a round names is fitted fully (fit_added)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.doctor.catalog import (
    CATALOG,
    HYSTERETIC,
    Candidate,
    EffectInstance,
    EffectName,
    scale_range,
    with_columns,
    with_scale,
)
from estimator.doctor.criteria import EquationTest, TestResult
from estimator.doctor.model import FittedModel, ModelStructure, Reference, build_extended
from estimator.equations import LinearResiduals
from estimator.newton_refit import MAX_NEWTON_ITERATIONS, newton_refit
from estimator.score_test import AddedColumnsScore, ScoreProfile, log_grid
from estimator.signals import MIN_CUTOFF_HZ
from estimator.solvers.exact import solve_exact

GAUSS_NEWTON_ITERATIONS = 4
HALVINGS = 3  # a Gauss-Newton step that raises the objective is halved at most this many times
GAUSS_NEWTON_STEP = {"delay": 5e-4, "lag": 5e-4, "average": 1e-3, "gain": 1e-3, "offset": 1e-4}
"""Finite-difference step of each kind of channel parameter (s, s, s, relative, m)."""
GAUSS_NEWTON_TOLERANCE = {"delay": 2e-6, "lag": 2e-6, "average": 4e-6, "gain": 1e-5, "offset": 1e-7}
NONNEGATIVE = frozenset({"delay", "lag", "average"})  # a sensor lags, it does not lead


def channel_limit_s(reference: Reference) -> float:
    """The longest delay, lag or averaging window searched: half a period of the excitation's top frequency
    (a longer delay turns the sweep's top past 180°, where it cannot be told from a lead: an alias); a top
    under identify's lowest cutoff (a plate that barely moved) counts as that cutoff."""
    return 0.5 / max(reference.filters.excitation_top_Hz, MIN_CUTOFF_HZ)


def feasible(kinds: list[str], values: np.ndarray, limit_s: float) -> np.ndarray:
    """Channel values moved into what a sensor can be: delay, lag, window in [0, limit_s], gain over −50%."""
    values = np.array(values, dtype=float)
    for j, kind in enumerate(kinds):
        if kind in NONNEGATIVE:
            values[j] = float(np.clip(values[j], 0.0, limit_s))
        elif kind == "gain":
            values[j] = max(values[j], -0.5)
    return values


def start_from(system: LinearResiduals, warm: FittedModel) -> np.ndarray:
    """θ of a similar model, matched by unknown name (new unknowns start at zero)."""
    return np.array([warm.value(name) for name in system.parameter_names])


def minimise(
    system: LinearResiduals, initial: np.ndarray | None, tolerance: float = 1e-10
) -> tuple[np.ndarray, float]:
    """θ minimising the paper's objective to `tolerance`, and the objective: from `initial` (a similar
    model's θ: near the optimum) by Newton steps alone, else (or if they do not converge) as identify does."""
    if initial is not None:
        polished = newton_refit(system, np.asarray(initial, dtype=float), tolerance=tolerance)
        if polished.iterations < MAX_NEWTON_ITERATIONS:
            return polished.theta, float(system.objective(polished.theta))
        initial = polished.theta
    solution = solve_exact(system, tolerance, initial=initial, certify=False)
    return solution.theta, solution.objective


def channel_jacobian(
    reference: Reference, model: FittedModel, which: list[int] | None = None
) -> dict[str, np.ndarray]:
    """Per Gauss-Newton parameter of the model (at the indices `which`, if given), the change of the equation
    residual per unit of it at the fitted θ, airborne samples held (also a channel family's Wald columns)."""
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
    """Identify `structure` on the reference recording from `warm` (a similar model, matched by unknown and
    channel parameter; new ones start at zero). A Gauss-Newton step that raises the objective is halved, at
    most HALVINGS times (a delay and a lag of one channel are nearly collinear; a clipped step overshoots)."""
    parameters = structure.channel_parameters
    kinds, limit_s = [kind for _, kind in parameters], channel_limit_s(reference)
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
            values = feasible(kinds, best.channel_values + step, limit_s)
            continue
        best, previous, halvings = model, model, 0
        tyre = model.tyre
        if final_pass or (not parameters and not (liftoff and steps == 0)):
            return model
        steps += 1
        if not parameters:
            continue  # once more with the airborne samples of the fitted tyre force
        moved = bounded_step(system, theta, channel_jacobian(reference, model), kinds, values, limit_s)
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
    limit_s: float,
    free_solution: np.ndarray | None = None,
) -> np.ndarray:
    """The channel values after one Gauss-Newton step within the bounds of `feasible` (active set): a
    parameter pushed past its bound is held there, the others solved again with its change in the offset
    (clipping afterwards would keep their share of a combined move). free_solution: the unbounded step."""
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
        increment[list(fixed)] = list(fixed.values())
        moved = feasible(kinds, values + increment, limit_s)
        clipped = [j for j in free if moved[j] != values[j] + increment[j]]
        if not clipped or len(free) == 1:
            return moved
        for j in clipped:
            fixed[j] = moved[j] - values[j]


def fit_added(
    reference: Reference, current: FittedModel, candidate: Candidate, start: FittedModel
) -> FittedModel:
    """The current model with the candidate's families added, identified from `start` (its one-step model), or
    from the current model when that ends worse (a larger model fits no worse; a step may start far off)."""
    structure = current.structure.with_effect(*candidate)
    model = fit(reference, structure, warm=start)
    return model if model.objective <= current.objective else fit(reference, structure, warm=current)


def one_step(
    reference: Reference, current: FittedModel, candidate: Candidate, screen: float | None = None
) -> tuple[FittedModel, TestResult]:
    """The current model with the candidate's families added and their unknowns moved by one linearised step,
    and the Wald test of those unknowns (their channel parameters' steps included) against zero.

    screen: a Wald p-value above which the candidate cannot be named; its channel step is then clipped into
    the bounds, not solved again within them (the model is only reported, not simulated)."""
    structure = current.structure.with_effect(*candidate)
    parameters = structure.channel_parameters
    vehicle, knots, values = reference.vehicle, reference.knots_m, current.channel_values_for(parameters)
    system, signals, airborne = build_extended(reference, structure, values, current.tyre)
    start = start_from(system, current)
    own = [k for k, (effect, _) in enumerate(parameters) if effect in candidate]
    model = FittedModel(
        structure, vehicle, start, system, signals, values, airborne, current.objective, knots
    )
    jacobian = channel_jacobian(reference, model, which=own)
    augmented = with_columns(system, jacobian, system.offset) if jacobian else system
    solution, objective = minimise(augmented, np.concatenate([start, np.zeros(len(jacobian))]))
    theta, steps = solution[: system.n_params], solution[system.n_params :]
    own_kinds = [parameters[k][1] for k in own]
    index = [k for k, n in enumerate(system.parameter_names) if n not in current.system.parameter_names]
    index += range(system.n_params, system.n_params + len(own))  # and the steps of its channel parameters
    test = EquationTest().test(augmented, solution, index, reference.recording.sample_time_s)
    limit_s, moved = channel_limit_s(reference), values[own] + steps
    clipped = feasible(own_kinds, moved, limit_s)
    if (screen is not None and test.p_value > screen) or np.array_equal(clipped, moved):
        values[own] = clipped
    else:
        # the test keeps the unbounded step; the model moves by the step within the bounds
        values[own] = bounded_step(system, start, jacobian, own_kinds, values[own], limit_s, solution)
        system, signals, airborne = build_extended(reference, structure, values, current.tyre)
        theta, objective = minimise(system, start)
    return FittedModel(structure, vehicle, theta, system, signals, values, airborne, objective, knots), test


@dataclass(frozen=True)
class ScaleProfile(ScoreProfile):
    """A low_speed_friction form's score profile at the current model over its catalog.scale_range,
    admissible where the one-step law is friction's (its forces at least 0: it dissipates, and its static
    level is not below the sliding one; a law that rises is a damper's)."""

    form: EffectInstance

    def form_at(self, index: int) -> EffectInstance:
        return with_scale(self.form, 2.0 ** self.grid_log2[index])

    def elastic(self, index: int) -> str | None:
        """Why a presliding build-up at the top of its range is no friction: it would not saturate within
        the deflection's travel, an elastic element (None otherwise)."""
        if self.form.variant == HYSTERETIC and index == self.grid_log2.size - 1:
            return "the build-up would not saturate within the deflection's travel: an elastic element"
        return None


def score_profile(
    reference: Reference, current: FittedModel, form: EffectInstance, grid_log2: np.ndarray | None = None
) -> ScaleProfile:
    """T(s) of the form over catalog.scale_range (or on the grid given: a bootstrap draw is profiled where
    the measurement was): the score test's gᵀS⁻¹g at the current model (estimator.score_test), twice the
    objective's fall by one Newton step with the form's columns added, a profile likelihood to first order."""
    if grid_log2 is None:
        grid_log2 = log_grid(*scale_range(form, current.signals.corners))
    score, family = AddedColumnsScore(current.system, current.theta), CATALOG[form.name]
    signals, airborne, knots = current.signals, current.airborne, current.knots_m
    steps = [
        score.of(family.columns(with_scale(form, 2.0**x), signals, airborne, knots, reference.identified))
        for x in grid_log2
    ]
    friction = np.array([bool(np.all(law >= 0.0)) for _, law in steps])
    return ScaleProfile(grid_log2, np.array([t for t, _ in steps]), friction, form)
