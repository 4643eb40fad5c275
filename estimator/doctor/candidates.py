"""Step 3 of the doctor's procedure (estimator.doctor.diagnose) for one candidate: its trial (one
linearised step from the current model, and its free simulation) and its tests' p-values, as measured and
as calibrated by the bootstrap's scales (a scaled χ², estimator.doctor.criteria)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from estimator.autocorrelation import effective_samples
from estimator.distributions import log_chi_square_survival
from estimator.doctor.catalog import Candidate, EffectName, label, members, unscaled
from estimator.doctor.criteria import (
    EachMember,
    ScaleSearch,
    SimulationTest,
    TestResult,
    intersection_union,
)
from estimator.doctor.fitting import ScaleProfile, one_step, score_profile
from estimator.doctor.model import FittedModel, Reference
from estimator.doctor.parameters import implausible, report
from estimator.doctor.result import CandidateScore
from estimator.doctor.simulation import simulate_models
from estimator.recording import Recording


@dataclass
class Simulated:
    """A model's free simulation: its gap (m) and output residual and prediction per channel."""

    gap_m: float
    residual: dict[str, np.ndarray]
    predicted: dict[str, np.ndarray]

    @cached_property
    def effective_samples(self) -> float:
        """The residual's effective number of independent samples, summed over its channels."""
        return float(sum(effective_samples(r) for r in self.residual.values()))


def free_simulations(models: list[FittedModel], recording: Recording) -> list[Simulated]:
    batch = simulate_models(models, recording)
    gaps = batch.gap_m()
    return [
        Simulated(float(gaps[k]), batch.column(k), {name: p[:, k] for name, p in batch.predicted.items()})
        for k in range(len(models))
    ]


def trial(
    reference: Reference,
    current: FittedModel,
    simulated: Simulated,
    candidate: Candidate,
    screen: float | None = None,
) -> tuple[CandidateScore, Candidate, ScaleProfile | None]:
    """Step 3 for one candidate: its one step from the current model and its tests. Both tests must
    reject: with `screen` (α), one whose equations give p above it cannot be named, and is not simulated.
    A low_speed_friction form has its scale searched first (fitting.score_profile): the friction law with
    the largest score statistic is stepped. (Run in a worker: the score, the scaled candidate and the
    profile are returned, not the stepped model, which is large.)"""
    profile = score_profile(reference, current, candidate[0]) if unscaled(candidate[0]) else None
    if profile is None:
        model, wald = one_step(reference, current, candidate, screen)
    else:  # the largest statistic whose fit is friction's (implausible: the step's law and the fit's differ)
        order, variation = profile.ranked()
        for best in order:
            candidate = (profile.form_at(best),)
            model, wald = one_step(reference, current, candidate, screen)
            if implausible(candidate[0], model) is None:
                break
    tried = screen is None or _equations(candidate, current, model, wald).p_value <= screen
    (outcome,) = free_simulations([model], reference.recording) if tried else (None,)
    score = score_candidate(candidate, current, simulated, model, wald, outcome)
    if profile is None:
        return score, candidate, None
    if reason := profile.elastic(best):
        score = replace(score, verdict=reason)
    # the search's variation, measured on √T, in units of √W (the Wald statistic the screen tests)
    to_wald = max(score.equation_statistic, 0.0) / max(float(profile.statistic[best]), 1e-300)
    return replace(score, search_variation=variation * math.sqrt(to_wald)), candidate, profile


def _equations(
    candidate: Candidate, current: FittedModel, model: FittedModel, wald: TestResult
) -> TestResult:
    """The candidate's test in the equations: the Wald test of its unknowns; tyre_liftoff has none, and
    passes when the equations hold better with it."""
    if candidate[0].name is EffectName.TYRE_LIFTOFF:
        better = model.objective < current.objective
        return TestResult(current.objective - model.objective, 0, 0.0 if better else 1.0)
    return wald


def score_candidate(
    candidate: Candidate,
    current: FittedModel,
    simulated: Simulated,
    model: FittedModel,
    wald: TestResult,
    outcome: Simulated | None,
) -> CandidateScore:
    """A candidate's tests (module docstring, step 3): the one-step Wald test of its unknowns and the
    likelihood ratio of its free simulation against the current model's (outcome None: not simulated, the
    equations decide: p above α there already)."""
    equations = _equations(candidate, current, model, wald)
    if outcome is None:
        simulation, gap, ratio = TestResult(math.nan, wald.unknowns, math.nan), None, None
        p_value = equations.p_value
    else:
        samples = simulated.effective_samples if np.isfinite(simulated.gap_m) else 0.0  # 0: diverged before
        simulation = SimulationTest().test(samples, simulated.gap_m, outcome.gap_m, wald.unknowns)
        gap, p_value = outcome.gap_m, intersection_union(equations, simulation)
        ratio = outcome.gap_m / simulated.gap_m if np.isfinite(simulated.gap_m) else None
    reason = next(filter(None, (implausible(e, model) for e in candidate)), None)
    if len(candidate) > 1 and reason is None and outcome is not None:
        index = members(candidate, model.system.parameter_names, current.system.parameter_names)
        reason = EachMember().redundant(model.system, model.theta, index, model.signals.sample_time_s)
    return CandidateScore(
        effect=label(candidate),
        objective_ratio=model.objective / current.objective,
        gap_m=gap,
        gap_ratio=ratio,
        equation_statistic=equations.statistic,
        simulation_statistic=simulation.statistic,
        unknowns=wald.unknowns,
        equation_p=equations.p_value,
        simulation_p=simulation.p_value,
        p_value=p_value,
        parameters=parameters_of(candidate, model),
        verdict=reason or "tested",
    )


def _log_p_values(score: CandidateScore, wald_scale: float, ratio_scale: float) -> tuple[float, float]:
    """ln of the candidate's equation and simulation p-values, the statistics divided by their calibration
    scales (tyre_liftoff's equation test is no Wald test: its p-value as it is)."""
    q = max(score.unknowns, 1)
    if score.effect.startswith(EffectName.TYRE_LIFTOFF.value):
        equation = math.log(score.equation_p) if score.equation_p > 0 else -math.inf
    else:
        searched = ScaleSearch(score.search_variation / math.sqrt(wald_scale))
        equation = searched.log_p(score.equation_statistic / wald_scale, q)
    if math.isnan(score.simulation_statistic):  # neither model simulates: the equations decide
        return equation, -math.inf
    return equation, log_chi_square_survival(max(score.simulation_statistic, 0.0) / ratio_scale, q)


def log_p_value(score: CandidateScore, wald_scale: float = 1.0, ratio_scale: float = 1.0) -> float:
    """ln of the candidate's p-value, the larger of its two tests' (for Selection: no underflow to 0)."""
    return max(_log_p_values(score, wald_scale, ratio_scale))


def calibrated(score: CandidateScore, wald_scale: float, ratio_scale: float) -> CandidateScore:
    """The score with its p-values from the statistics divided by their bootstrap scales."""
    equation, simulation = (min(1.0, math.exp(v)) for v in _log_p_values(score, wald_scale, ratio_scale))
    if score.effect.startswith(EffectName.TYRE_LIFTOFF.value):
        equation = score.equation_p
    return replace(score, equation_p=equation, simulation_p=simulation, p_value=max(equation, simulation))


def calibration_scales(
    score: CandidateScore, values: tuple[list[float], list[float]], draws: int | None = None
) -> tuple[float, float]:
    """A candidate's Wald and likelihood-ratio scales (calibrate): the mean of its finite statistics on the
    draws, or their sum over `draws` (a lower bound), over the degrees of freedom, at least 1."""
    q = max(score.unknowns, 1)
    return tuple(  # type: ignore[return-value]
        max(1.0, sum(kept) / ((draws or len(kept)) * q)) if kept else 1.0 for kept in values
    )


def parameters_of(candidate: Candidate, model: FittedModel) -> dict[str, float | str]:
    return {key: value for effect in candidate for key, value in report(effect, model).items()}


def verdict_of(
    score: CandidateScore, candidate: Candidate, chosen: Candidate | None, bound: float, waiting: list
) -> CandidateScore:
    if score.verdict != "tested":
        return score
    if candidate == chosen:
        return replace(score, verdict="named")
    if score.p_value > bound:
        untried = ": not simulated" if score.gap_m is None else ""
        verdict = f"not significant (p = {score.p_value:.2g} > α/m = {bound:.2g}){untried}"
        return replace(score, verdict=verdict)
    if candidate in waiting:
        return replace(score, verdict="significant, but one of its families alone is too (tested first)")
    return replace(score, verdict="significant, but another candidate is more so")


def evidence_of(score: CandidateScore) -> str:
    ratio = f"{score.gap_ratio:.2f}x" if score.gap_ratio is not None else "finite (it diverged before)"
    return (
        f"equations: W = {score.equation_statistic:.1f} on {score.unknowns} unknowns "
        f"(p = {score.equation_p:.2g}); simulation: the gap {ratio} (likelihood ratio "
        f"{score.simulation_statistic:.1f}, p = {score.simulation_p:.2g})"
    )
