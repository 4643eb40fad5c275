"""The model doctor's procedure, top to bottom: find where the identified model and the measurement disagree,
name the missing effect, add it, and show the gap shrink; say "unexplained", and where, when the final model
leaves more than its own noise would.

1. *Start* from what `identify` fits (the paper's model with the `--tyre` option's tyre), its damper curve
   resolved near zero velocity (estimator.doctor.model). Constants the vehicle file does not state are
   identified first and then held like stated ones.
2. *A round*: every family of the catalogue the model lacks (estimator.doctor.catalog) is added in turn and
   the model identified with it (the paper's objective, exact solver; channel parameters by Gauss-Newton
   steps); all of them are simulated from the measured plate in one run.
3. *Each candidate is tested* (estimator.doctor.criteria): in the equations (a Wald test of its unknowns)
   and in the free simulation (a likelihood ratio of the gap); its p-value is the larger of the two. A
   candidate whose fitted values are physically impossible (estimator.doctor.parameters.implausible) is not
   named whatever its p-value.
4. *Calibrate*: a candidate significant as it stands has both statistics divided by their mean over bootstrap
   draws of the current model (a scaled χ²; calibrate). *Select*: the candidate with the smallest p-value is
   named when it is at most α/m (Bonferroni over the m candidates of the round). Repeat from 2 with it added,
   until a round names nothing.
5. *Goodness of fit*: the final model against a parametric bootstrap of itself; p < α: "unexplained", with
   where the disagreement is largest (estimator.doctor.residuals.Localisation).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import cached_property
from typing import TypeVar

import numpy as np

from estimator.doctor.catalog import CATALOG, EffectInstance, EffectName
from estimator.doctor.criteria import (
    ALPHA,
    GoodnessOfFit,
    Selection,
    SimulationTest,
    TestResult,
    intersection_union,
)
from estimator.doctor.expected import plausible_truth, refit_on, synthetic_recording
from estimator.doctor.fitting import fit, fit_added
from estimator.doctor.model import FitSettings, FittedModel, ModelStructure, Reference, starting_structure
from estimator.doctor.noise import measure_noise
from estimator.doctor.parameters import implausible, report
from estimator.doctor.residuals import (
    chi_square_survival,
    effective_samples,
    locate,
    log_chi_square_survival,
    sweep_frequency_Hz,
)
from estimator.doctor.result import CandidateScore, DiagnosisResult, DiagnosisStep
from estimator.doctor.screening import one_step
from estimator.doctor.simulation import diverged, simulate_models
from estimator.identify import IdentifyOptions, identify
from estimator.recording import Recording
from estimator.vehicle import TyreModel, VehicleParameters

Item = TypeVar("Item")
Value = TypeVar("Value")

DEFAULT_POINTS = {"quarter-car": 30, "axle": 15}
"""Damper curve points per side before the low-speed knots (1.5 times identify's default: the curve of a
diagnosis must follow a smooth damper closely enough that its own approximation is not taken for an
effect)."""


@dataclass(frozen=True)
class DiagnoseOptions:
    """tyre, points, nsample: the starting model, as for identify (points: DEFAULT_POINTS unless given).
    alpha: the family-wise error rate of a round and the goodness-of-fit test's false-alarm rate; draws:
    the bootstrap's size; max_steps: at most this many effects are named."""

    tyre: TyreModel = TyreModel.MAXWELL
    points: int | None = None
    nsample: int | None = 5000
    alpha: float = ALPHA
    draws: int = 8
    max_steps: int = 6
    seed: int = 0
    """Seed of the bootstrap's noise (draw k uses seed + k)."""
    workers: int = 2
    """Threads the fits of a round run in (the diagnosis does not depend on it)."""


@dataclass(frozen=True)
class DiagnoseProgress:
    step: int
    stage: str


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


def _simulate(models: list[FittedModel], recording: Recording) -> list[Simulated]:
    batch = simulate_models(models, recording)
    gaps = batch.gap_m()
    return [
        Simulated(
            float(gaps[k]),
            batch.column(k),
            {name: p[:, k] for name, p in batch.predicted.items()},
        )
        for k in range(len(models))
    ]


class _Doctor:
    def __init__(
        self,
        reference: Reference,
        options: DiagnoseOptions,
        progress: Callable[[DiagnoseProgress], object] | None,
        cancel: threading.Event | None,
    ) -> None:
        self.reference = reference
        self.recording = reference.recording
        self.options = options
        self.progress = progress
        self.cancel = cancel
        self.pool: ThreadPoolExecutor | None = None

    def map(self, function: Callable[[Item], Value], items: Iterable[Item]) -> list[Value]:
        """function over items, in the pool's threads (the heavy parts of a fit release the GIL)."""
        if self.pool is None:
            return [function(item) for item in items]
        return list(self.pool.map(function, items))

    def report(self, step: int, stage: str) -> None:
        if self.cancel is not None and self.cancel.is_set():
            raise InterruptedError("diagnosis cancelled")
        if self.progress is not None:
            self.progress(DiagnoseProgress(step, stage))

    def candidates(self, structure: ModelStructure) -> list[EffectInstance]:
        """The families the model lacks (a family with variants, sensor_dynamics per channel or
        low_speed_friction, is added in one variant only)."""
        present = {(e.name, e.channel) for e in structure.effects}
        vehicle, reference = self.reference.vehicle, self.reference
        return [
            instance
            for effect in CATALOG.values()
            for instance in effect.instances(vehicle, self.recording, reference.identified)
            if (instance.name, instance.channel) not in present
        ]

    def run(self) -> DiagnosisResult:
        if self.options.workers <= 1:
            return self.diagnose()
        with ThreadPoolExecutor(self.options.workers) as pool:
            self.pool = pool
            try:
                return self.diagnose()
            finally:
                self.pool = None

    def diagnose(self) -> DiagnosisResult:
        options, reference = self.options, self.reference
        structure = starting_structure(options.tyre)
        self.report(0, "identifying the starting model")
        current = fit(reference, structure)
        (simulated,) = _simulate([current], self.recording)
        initial, start = simulated, current
        steps: list[DiagnosisStep] = []
        rounds: list[list[CandidateScore]] = []
        for step in range(options.max_steps + 1):
            self.report(step, "fitting and testing the candidates")
            candidates = self.candidates(structure) if step < options.max_steps else []
            if not candidates:
                break
            stepped = self.map(lambda c, warm=current: one_step(reference, warm, c), candidates)
            outcomes = _simulate([m for m, _ in stepped], self.recording)
            scores, log_p = [], {}
            for candidate, (model, equations), outcome in zip(candidates, stepped, outcomes, strict=True):
                score = self.score(candidate, current, simulated, model, equations, outcome)
                scores.append(score)
                if score.verdict == "tested":
                    log_p[candidate] = _log_p(score)
            bound = options.alpha / max(len(log_p), 1)
            # calibration can only raise a p-value (its scales are at least 1): only the candidates that
            # are significant uncalibrated need the bootstrap
            significant = [c for c in log_p if log_p[c] <= math.log(bound)]
            if significant:
                self.report(step, "calibrating the significant candidates by a bootstrap of the model")
                observed = {c: scores[candidates.index(c)] for c in significant}
                scales = self.calibrate(current, simulated, observed, bound)
                for candidate in significant:
                    k = candidates.index(candidate)
                    scores[k] = _calibrated(scores[k], *scales[candidate])
                    log_p[candidate] = _log_p(scores[k], *scales[candidate])
            chosen = Selection(options.alpha).choose(log_p)
            scores = [_verdict(s, chosen, bound) for s in scores]
            rounds.append(scores)
            if chosen is None:
                break
            index = candidates.index(chosen)
            self.report(step, f"fitting {chosen.label}")
            model = fit_added(reference, current, chosen, stepped[index][0])
            (outcome,) = _simulate([model], self.recording)
            steps.append(
                DiagnosisStep(
                    effect=chosen.label,
                    parameters=report(chosen, model),
                    gap_before_m=simulated.gap_m,
                    gap_after_m=outcome.gap_m,
                    evidence=_evidence(scores[index]),
                    p_value=scores[index].p_value,
                    located_after=locate(model, outcome.residual, outcome.gap_m),
                    predicted_after=outcome.predicted,
                )
            )
            structure, current, simulated = model.structure, model, outcome
        self.report(len(steps), "testing the final model against its own noise")
        return self.conclude(start, initial, current, simulated, steps, rounds)

    def score(
        self,
        candidate: EffectInstance,
        current: FittedModel,
        simulated: Simulated,
        model: FittedModel,
        equations: TestResult,
        outcome: Simulated,
    ) -> CandidateScore:
        """The candidate's tests on the recording (module docstring, step 3)."""
        return score_candidate(candidate, current, simulated, model, equations, outcome)

    def conclude(
        self,
        start: FittedModel,
        initial: Simulated,
        final: FittedModel,
        simulated: Simulated,
        steps: list[DiagnosisStep],
        rounds: list[list[CandidateScore]],
    ) -> DiagnosisResult:
        """The goodness-of-fit test of the final model and the diagnosis in words."""
        objectives, gaps = self.bootstrap(final, simulated)
        gof = GoodnessOfFit(self.options.alpha)
        p = gof.p_value(simulated.gap_m, gaps)
        unexplained = gof.unexplained(p)
        located = locate(final, simulated.residual, simulated.gap_m)
        finite = [g for g in gaps if np.isfinite(g)]
        expected = float(np.mean(finite)) if finite else float("inf")
        named = ", ".join(s.effect for s in steps)
        gap, before = simulated.gap_m * 1e6, initial.gap_m * 1e6
        verdict = (
            f"p = {p:.2g} < α = {self.options.alpha:g}: unexplained; " + located.describe()
            if unexplained
            else f"p = {p:.2g}: nothing left that the noise does not explain"
        )
        if steps:
            conclusion = f"named {named}: the gap fell from {before:.1f} µm to {gap:.1f} µm; {verdict}"
        else:
            conclusion = f"nothing named: the gap is {gap:.1f} µm; {verdict}"
        plate = self.recording.channels["x_r_l" if final.vehicle.is_axle else "x_r"]
        return DiagnosisResult(
            starting_effects=start.structure.labels,
            final_effects=final.structure.labels,
            gap_before_m=initial.gap_m,
            gap_after_m=simulated.gap_m,
            steps=steps,
            rounds=rounds,
            unexplained=bool(unexplained),
            conclusion=conclusion,
            expected_gap_m=expected,
            residual_ratio=final.objective / float(np.mean(objectives)) if objectives else float("nan"),
            p_value=p,
            alpha=self.options.alpha,
            where=located.describe() if unexplained else None,
            noise_floor_m=self.reference.filters.noise_floor_m,
            located_before=locate(start, initial.residual, initial.gap_m),
            measured={n: self.recording.channels[n] for n in initial.predicted},
            predicted_before=initial.predicted,
            time_s=self.recording.time_s,
            sweep_frequency_Hz=sweep_frequency_Hz(plate, self.recording.sample_time_s),
            final_model=final,
        )

    def synthetic(self, model: FittedModel, simulated: Simulated, plausible: bool = True) -> list[Recording]:
        """`draws` synthetic recordings of the model's smooth response (its plausible truth) read with the
        recording's own noise, measured on the model's output residual (estimator.doctor.expected,
        estimator.doctor.noise); none when the truth diverges."""
        recording, dt = self.recording, self.recording.sample_time_s
        truth = (
            plausible_truth(model, recording, self.reference.settings, self.reference.identified)
            if plausible
            else model
        )
        (response,) = _simulate([truth], recording)
        if not np.isfinite(response.gap_m):
            return []
        measured = {name: recording.channels[name] for name in simulated.residual}
        residual = {
            name: measured[name] if diverged(r, measured[name]) else r
            for name, r in simulated.residual.items()
        }
        noise = measure_noise(residual, measured, dt, self.reference.filters.excitation_top_Hz)
        return [
            synthetic_recording(recording, response.predicted, noise, self.options.seed + k)
            for k in range(self.options.draws)
        ]

    def calibrate(
        self,
        current: FittedModel,
        simulated: Simulated,
        observed: dict[EffectInstance, CandidateScore],
        bound: float,
    ) -> dict[EffectInstance, tuple[float, float]]:
        """Per candidate, the scales of its Wald and likelihood-ratio statistics under the current model:
        their mean over the bootstrap draws (the current structure and the candidate identified on each
        synthetic recording, as on the measurement; a statistic below 0 counts as 0) over their degrees of
        freedom, at least 1 (a scaled χ²: the model's own approximation and the noise's colour inflate both
        statistics alike on the measurement and on the draws).

        The draws are made `workers` at a time. Every statistic is at least 0, so the sum over the draws made,
        spread over all `draws`, is a lower bound of a scale: a candidate whose p-value at those lower bounds
        is already above `bound` (its round's α/m) cannot be named whatever the other draws give, and is not
        stepped on them (its scales are then the mean over the draws it had); the draws stop when no candidate
        is left. The round's decision is the one every draw would give."""
        synthetic = self.synthetic(current, simulated, plausible=False)
        if not synthetic:
            return {c: (1.0, 1.0) for c in observed}
        values: dict[EffectInstance, tuple[list[float], list[float]]] = {c: ([], []) for c in observed}
        alive = list(observed)
        for first in range(0, len(synthetic), max(self.options.workers, 1)):
            chunk = synthetic[first : first + max(self.options.workers, 1)]
            for draw in self.map(lambda r, cs=tuple(alive): self.draw_statistics(current, r, cs), chunk):
                for candidate, statistics in draw.items():
                    for kept, statistic in zip(values[candidate], statistics, strict=True):
                        if np.isfinite(statistic):
                            kept.append(max(statistic, 0.0))
            alive = [
                c
                for c in alive
                if _log_p(observed[c], *_scales(observed[c], values[c], len(synthetic))) <= math.log(bound)
            ]
            if not alive:
                break
        return {c: _scales(observed[c], values[c]) for c in observed}

    def draw_statistics(
        self, current: FittedModel, recording: Recording, candidates: tuple[EffectInstance, ...]
    ) -> dict[EffectInstance, tuple[float, float]]:
        """On one synthetic recording: the current structure identified, each candidate stepped from it and
        tested as on the measurement; its Wald and likelihood-ratio statistics."""
        on = Reference.of(recording, current.vehicle, self.reference.settings, self.reference.identified)
        on = replace(on, knots_m=self.reference.knots_m)
        base = fit(on, current.structure, warm=current)
        stepped = [one_step(on, base, c) for c in candidates]
        outcomes = _simulate([base, *(m for m, _ in stepped)], recording)
        return {
            c: (score.equation_statistic, score.simulation_statistic)
            for c, score in zip(
                candidates,
                (
                    score_candidate(c, base, outcomes[0], m, t, o)
                    for c, (m, t), o in zip(candidates, stepped, outcomes[1:], strict=True)
                ),
                strict=True,
            )
        }

    def bootstrap(self, final: FittedModel, simulated: Simulated) -> tuple[list[float], list[float]]:
        """The equation objective and gap of the final structure re-identified on the synthetic recordings
        of itself."""
        recording = self.recording
        synthetic = self.synthetic(final, simulated)
        if not synthetic:
            return [], []
        refits = self.map(lambda s: refit_on(s, final, self.reference), synthetic)
        batch = simulate_models(refits, recording, list(synthetic))
        return [m.objective for m in refits], [float(g) for g in batch.gap_m()]


def score_candidate(
    candidate: EffectInstance,
    current: FittedModel,
    simulated: Simulated,
    model: FittedModel,
    equations: TestResult,
    outcome: Simulated,
) -> CandidateScore:
    """A candidate's tests (module docstring, step 3): the one-step Wald test of its unknowns
    (estimator.doctor.screening) and the likelihood ratio of its free simulation against the current
    model's."""
    unknowns = equations.unknowns
    if candidate.name is EffectName.TYRE_LIFTOFF:  # no unknown: the equations must hold better with it
        better = model.objective < current.objective
        equations = TestResult(current.objective - model.objective, 0, 0.0 if better else 1.0)
    samples = simulated.effective_samples if np.isfinite(simulated.gap_m) else 0.0  # 0: diverged before
    simulation = SimulationTest().test(samples, simulated.gap_m, outcome.gap_m, unknowns)
    reason = implausible(candidate, model)
    return CandidateScore(
        effect=candidate.label,
        objective_ratio=model.objective / current.objective,
        gap_m=outcome.gap_m,
        gap_ratio=outcome.gap_m / simulated.gap_m if np.isfinite(simulated.gap_m) else None,
        equation_statistic=equations.statistic,
        simulation_statistic=simulation.statistic,
        unknowns=unknowns,
        equation_p=equations.p_value,
        simulation_p=simulation.p_value,
        p_value=intersection_union(equations, simulation),
        parameters=report(candidate, model),
        verdict=reason or "tested",
    )


def _log_p(score: CandidateScore, wald_scale: float = 1.0, ratio_scale: float = 1.0) -> float:
    """ln of the candidate's p-value (the larger of its two tests', the statistics divided by their
    calibration scales), without the underflow of score.p_value (Selection)."""
    q = max(score.unknowns, 1)
    if score.effect.startswith(EffectName.TYRE_LIFTOFF.value):  # no unknown: not a Wald test
        equation = math.log(score.equation_p) if score.equation_p > 0 else -math.inf
    else:
        equation = log_chi_square_survival(score.equation_statistic / wald_scale, q)
    if math.isnan(score.simulation_statistic):  # neither model simulates: the equations decide
        simulation = -math.inf
    else:
        simulation = log_chi_square_survival(max(score.simulation_statistic, 0.0) / ratio_scale, q)
    return max(equation, simulation)


def _scales(
    score: CandidateScore, values: tuple[list[float], list[float]], draws: int | None = None
) -> tuple[float, float]:
    """The Wald and likelihood-ratio scales of a candidate from its statistics on the draws (calibrate):
    their mean over the draws with a finite value, or their sum over `draws` (a lower bound of that mean
    once all draws are made), over the degrees of freedom, at least 1."""
    q = max(score.unknowns, 1)
    return tuple(  # type: ignore[return-value]
        max(1.0, sum(kept) / ((draws or len(kept)) * q)) if kept else 1.0 for kept in values
    )


def _calibrated(score: CandidateScore, wald_scale: float, ratio_scale: float) -> CandidateScore:
    """The score with its p-values from the statistics divided by their bootstrap scales."""
    q = max(score.unknowns, 1)
    equation_p = chi_square_survival(score.equation_statistic / wald_scale, q)
    positive = score.simulation_statistic > 0
    simulation_p = chi_square_survival(score.simulation_statistic / ratio_scale, q) if positive else 1.0
    if math.isnan(score.simulation_statistic):  # neither model simulates (SimulationTest)
        simulation_p = 0.0
    if score.effect.startswith(EffectName.TYRE_LIFTOFF.value):
        equation_p = score.equation_p  # no unknown: its equation test is not a Wald test
    return replace(
        score, equation_p=equation_p, simulation_p=simulation_p, p_value=max(equation_p, simulation_p)
    )


def _verdict(score: CandidateScore, chosen: EffectInstance | None, bound: float) -> CandidateScore:
    if score.verdict != "tested":
        return score
    if chosen is not None and score.effect == chosen.label:
        return replace(score, verdict="named")
    if score.p_value > bound:
        return replace(score, verdict=f"not significant (p = {score.p_value:.2g} > α/m = {bound:.2g})")
    return replace(score, verdict="significant, but another candidate is more so")


def _evidence(score: CandidateScore) -> str:
    ratio = f"{score.gap_ratio:.2f}x" if score.gap_ratio is not None else "finite (it diverged before)"
    return (
        f"equations: W = {score.equation_statistic:.1f} on {score.unknowns} unknowns "
        f"(p = {score.equation_p:.2g}); simulation: the gap {ratio} (likelihood ratio "
        f"{score.simulation_statistic:.1f}, "
        f"p = {score.simulation_p:.2g})"
    )


def diagnose(
    recording: Recording,
    vehicle: VehicleParameters,
    options: DiagnoseOptions = DiagnoseOptions(),
    progress: Callable[[DiagnoseProgress], object] | None = None,
    cancel: threading.Event | None = None,
) -> DiagnosisResult:
    """Find, name and add the effects the model lacks (module docstring); `progress` is called at every
    stage, `cancel` (set from another thread) stops the diagnosis with InterruptedError."""
    identified = vehicle.unknown
    if vehicle.unknown:
        if progress is not None:
            progress(DiagnoseProgress(0, "identifying the constants the vehicle file does not state"))
        found = identify(recording, vehicle, IdentifyOptions(points=options.points, output_error=False))
        vehicle = found.model.vehicle
    points = options.points or DEFAULT_POINTS[vehicle.model.value]
    reference = Reference.of(recording, vehicle, FitSettings(points, options.nsample), identified)
    return _Doctor(reference, options, progress, cancel).run()
