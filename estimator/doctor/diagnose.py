"""The model doctor's procedure, top to bottom: find where the identified model and the measurement disagree,
name the missing effect, add it, and show the gap shrink; say "unexplained", and where, when the final model
leaves more than its own noise would.

1. *Start* from what `identify` fits (the paper's model with the `--tyre` option's tyre), its damper curve
   resolved near zero velocity (estimator.doctor.model). Constants the vehicle file does not state are
   identified first (with the stated rates free meanwhile) and then held like stated ones.
2. *A round*: every family of the catalogue the model lacks (estimator.doctor.catalog) is added in turn, and
   the load path's two rates together (catalog.LOAD_PATH), and its unknowns moved by one linearised step from
   the current model (fitting.one_step: the paper's objective, exact solver; channel parameters by a
   Gauss-Newton step; a friction form at the scale its score profile finds), side by side in forked processes.
3. *Each candidate is tested* (estimator.doctor.candidates, criteria): in the equations (a Wald test of
   its unknowns) and in the free simulation from the measured plate (a likelihood ratio of the gap); its
   p-value is the larger of the two (one with p > α in the equations is not simulated). A candidate whose
   fitted values are physically impossible (estimator.doctor.parameters.implausible), or families together
   one of which the others make redundant (criteria.EachMember), is not named whatever its p-value.
4. *Calibrate*: a candidate significant as it stands has both statistics divided by their mean over bootstrap
   draws of the current model (a scaled χ²; calibrate; a friction form's profile scale by scale, its search
   paid for by Davies' bound, criteria.ScaleSearch). *Select*: the candidate with the smallest p-value is
   named when it is at most α/m (Bonferroni over the round's m; families together wait for their members,
   criteria.Selection); it is fitted fully (fitting.fit_added; if that fit is impossible, the next). Repeat
   from 2 until a round names nothing; the model kept is the path's with the smallest gap (later steps: said).
5. *Goodness of fit*: the final model against a parametric bootstrap of its plausible truth
   (estimator.doctor.expected); p < α: "unexplained", with where the disagreement is largest
   (estimator.doctor.residuals.Localisation); the model handed out then has its curve refined on the
   free-simulation gap (estimator.validation.refined_on: what the model lacks biases the equations' fit).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from estimator.doctor.candidates import (
    Simulated,
    calibrated,
    calibration_scales,
    evidence_of,
    free_simulations,
    log_p_value,
    parameters_of,
    trial,
    verdict_of,
)
from estimator.doctor.catalog import CATALOG, Candidate, label, round_candidates
from estimator.doctor.criteria import ALPHA, GoodnessOfFit, Selection
from estimator.doctor.expected import plausible_truth, synthetic_recordings
from estimator.doctor.fitting import ScaleProfile, fit, fit_added, one_step, score_profile
from estimator.doctor.model import FitSettings, FittedModel, Reference, starting_structure
from estimator.doctor.parameters import implausible
from estimator.doctor.residuals import locate
from estimator.doctor.result import CandidateScore, DiagnosisResult, DiagnosisStep, model_json
from estimator.doctor.simulation import simulate_models
from estimator.forked_map import forked_map
from estimator.identify import identify_unstated
from estimator.model_io import ModelFormatError, model_from_json
from estimator.output_error import IdentifiedModel
from estimator.recording import Recording
from estimator.signals import sweep_frequency_Hz
from estimator.solvers.differential_evolution import DEProgress
from estimator.validation import refined_on
from estimator.vehicle import TyreModel, VehicleConstant, VehicleParameters

TESTED_RATES = frozenset({VehicleConstant.SPRING, VehicleConstant.TYRE})  # by spring_curve, tyre_stiffness
DEFAULT_POINTS = {"quarter-car": 30, "axle": 15}
"""Damper curve points per side before the low-speed knots: 1.5 times identify's default, so that the curve's
own approximation of a smooth damper is not taken for an effect."""


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
    seed: int = 0  # of the bootstrap's noise (draw k uses seed + k)
    workers: int = 2  # processes the fits of a round run in (the diagnosis does not depend on it)


@dataclass(frozen=True)
class DiagnoseProgress:
    step: int
    stage: str
    generation: DEProgress | None = None  # within the stage, a DE's (the final model's refinement)


@dataclass
class _Doctor:
    reference: Reference
    options: DiagnoseOptions
    progress: Callable[[DiagnoseProgress], object] | None
    cancel: threading.Event | None

    def map(self, function: Callable, items: list) -> list:
        """function over items in `workers` processes (estimator.forked_map: results must be small)."""
        return forked_map(function, items, self.options.workers)

    def refit(self, model: FittedModel, recording: Recording) -> tuple[float, float]:
        """Step 5 on one synthetic recording: the objective and gap (m) of the structure fitted on it."""
        refit = fit(self.reference.on(recording), model.structure, warm=model)
        batch = simulate_models([refit], self.reference.recording, [recording])
        return refit.objective, float(batch.gap_m()[0])

    def report(self, step: int, stage: str) -> None:
        if self.cancel is not None and self.cancel.is_set():
            raise InterruptedError("diagnosis cancelled")
        if self.progress is not None:
            self.progress(DiagnoseProgress(step, stage))

    def diagnose(self) -> DiagnosisResult:
        """Steps 1 to 5 of the module docstring."""
        options, reference, recording = self.options, self.reference, self.reference.recording
        self.report(0, "identifying the starting model")
        start = current = fit(reference, starting_structure(options.tyre))  # step 1
        (initial,) = free_simulations([current], recording)
        simulated, path = initial, [(current, initial)]  # the model and its simulation after each step
        steps: list[DiagnosisStep] = []
        rounds: list[list[CandidateScore]] = []
        for step in range(options.max_steps + 1):
            self.report(step, "fitting and testing the candidates")
            # step 2: the families the model lacks (a family with variants, per channel or form, in one only)
            present = {(e.name, e.channel) for e in current.structure.effects}
            singles = [
                c
                for effect in CATALOG.values()
                for c in effect.instances(reference.vehicle, recording, reference.identified)
                if (c.name, c.channel) not in present
            ]
            candidates = round_candidates(singles)
            if not candidates or step == options.max_steps:
                break
            round_of = partial(trial, reference, current, simulated, screen=options.alpha)
            tried = self.map(round_of, candidates)  # steps 2 and 3 (friction's scales searched)
            scores, candidates = [s for s, _, _ in tried], [c for _, c, _ in tried]
            profiles = {c: p for _, c, p in tried if p is not None}
            log_p = {
                c: log_p_value(s) for c, s in zip(candidates, scores, strict=True) if s.verdict == "tested"
            }
            bound = (selection := Selection(options.alpha)).bound(len(log_p))
            # step 4: calibration only raises p-values (scales ≥ 1): the bootstrap for the significant only
            significant = [c for c in log_p if log_p[c] <= math.log(bound)]
            if significant:
                self.report(step, "calibrating the significant candidates by a bootstrap of the model")
                observed = {c: scores[candidates.index(c)] for c in significant}
                calibrations = self.calibrate(current, simulated, observed, bound, profiles)
                for candidate, (*scales, profile_scales) in calibrations.items():
                    k, screened = candidates.index(candidate), -math.inf
                    if profile_scales is not None:  # the profile standardised scale by scale, chosen again
                        screened = log_p.pop(candidate)
                        scores[k], candidates[k], scales = self.rescaled(
                            current, simulated, profiles[candidate], profile_scales, scales[1]
                        )
                    if scores[k].verdict == "tested":  # (a profiled form: both its tests must reject)
                        scores[k] = calibrated(scores[k], *scales)
                        log_p[candidates[k]] = max(screened, log_p_value(scores[k], *scales))
            left = dict(log_p)
            gaps = {c: s.gap_m for c, s in zip(candidates, scores, strict=True) if s.gap_m is not None}
            while (chosen := selection.choose(left, len(log_p), gaps)) is not None:
                self.report(step, f"fitting {label(chosen)}")
                model = fit_added(reference, current, chosen, one_step(reference, current, chosen)[0])
                if not (reason := next(filter(None, (implausible(e, model) for e in chosen)), None)):
                    break
                # impossible once fitted fully (its one step was not): the next most significant
                del left[chosen]
                k = candidates.index(chosen)
                scores[k] = replace(scores[k], verdict=f"{reason} once fitted fully")
            waits = selection.waiting(log_p, len(log_p))
            scores = [verdict_of(s, c, chosen, bound, waits) for s, c in zip(scores, candidates, strict=True)]
            rounds.append(scores)
            if chosen is None:
                break
            index = candidates.index(chosen)
            (outcome,) = free_simulations([model], recording)
            steps.append(
                DiagnosisStep(
                    effect=label(chosen),
                    parameters=parameters_of(chosen, model),
                    gap_before_m=simulated.gap_m,
                    gap_after_m=outcome.gap_m,
                    evidence=evidence_of(scores[index]),
                    p_value=scores[index].p_value,
                    located_after=locate(model, outcome.residual, outcome.gap_m),
                    predicted_after=outcome.predicted,
                )
            )
            current, simulated = model, outcome
            path.append((model, outcome))
        # steps are named on one-step evidence; the path's model that simulates best is kept (first of equals)
        best, left_out = int(np.argmin([s.gap_m for _, s in path])), ""
        if best < len(steps):
            left_out = f"; left out {', '.join(s.effect for s in steps[best:])}: the gap rose with them"
            steps, (current, simulated) = steps[:best], path[best]
        self.report(len(steps), "testing the final model against its own noise")
        # step 5: the structure re-identified (from the final model) on its plausible truth's response + noise
        final, synthetic = current, self.synthetic(current, simulated)
        refits = self.map(lambda s: self.refit(final, s), synthetic)
        objectives, gaps = [o for o, _ in refits], [g for _, g in refits]
        gof = GoodnessOfFit(options.alpha)
        p = gof.p_value(simulated.gap_m, gaps)
        unexplained = gof.unexplained(p)
        located = locate(final, simulated.residual, simulated.gap_m)
        finite = [g for g in gaps if np.isfinite(g)]
        verdict = (
            f"p = {p:.2g} < α = {options.alpha:g}: unexplained; " + located.describe()
            if unexplained
            else f"p = {p:.2g}: nothing left that the noise does not explain"
        )
        effects = ", ".join(s.effect for s in steps)
        plate = recording.channels["x_r_l" if final.vehicle.is_axle else "x_r"]
        return DiagnosisResult(
            starting_effects=start.structure.labels,
            final_effects=final.structure.labels,
            gap_before_m=initial.gap_m,
            gap_after_m=simulated.gap_m,
            steps=steps,
            rounds=rounds,
            unexplained=bool(unexplained),
            conclusion=gap_words(effects, initial.gap_m, simulated.gap_m) + f"{left_out}; {verdict}",
            expected_gap_m=float(np.mean(finite)) if finite else float("inf"),
            residual_ratio=final.objective / float(np.mean(objectives)) if objectives else float("nan"),
            p_value=p,
            alpha=options.alpha,
            where=located.describe() if unexplained else None,
            noise_floor_m=reference.filters.noise_floor_m,
            located_before=locate(start, initial.residual, initial.gap_m),
            measured={n: recording.channels[n] for n in initial.predicted},
            predicted_before=initial.predicted,
            time_s=recording.time_s,
            sweep_frequency_Hz=sweep_frequency_Hz(plate, recording.sample_time_s),
            final_model=final,
        )

    def synthetic(self, model: FittedModel, simulated: Simulated, plausible: bool = True) -> list[Recording]:
        """`draws` recordings of the model's (or its plausible truth's) response read with the noise measured
        on its output residual; none when the truth diverges."""
        reference, recording = self.reference, self.reference.recording
        (response,) = free_simulations([plausible_truth(model, reference) if plausible else model], recording)
        if not np.isfinite(response.gap_m):
            return []
        seeds = range(self.options.seed, self.options.seed + self.options.draws)
        return synthetic_recordings(reference, response.predicted, simulated.residual, seeds)

    def calibrate(
        self,
        current: FittedModel,
        simulated: Simulated,
        observed: dict[Candidate, CandidateScore],
        bound: float,
        profiles: dict[Candidate, ScaleProfile],
    ) -> dict[Candidate, tuple[float, float, np.ndarray | None]]:
        """Per candidate, the scales of its Wald and likelihood-ratio statistics under the current model:
        their mean over bootstrap draws of it (each tested as the measurement; below 0 counts as 0) over the
        degrees of freedom, at least 1 (a scaled χ²: the model's own approximation and the noise's colour
        inflate both statistics alike on the measurement and on the draws).

        The draws are made `workers` at a time. A sum over the draws made, spread over all `draws`, is a
        lower bound of a scale: a candidate whose p-value at those bounds is already above `bound` cannot be
        named, and is left out of the other draws; the round's decision is the one every draw would give."""
        synthetic = self.synthetic(current, simulated, plausible=False)
        if not synthetic:
            return {c: (1.0, 1.0, None) for c in observed}
        values: dict[Candidate, tuple[list[float], list[float]]] = {c: ([], []) for c in observed}
        traces: dict[Candidate, list[np.ndarray]] = {c: [] for c in observed if c in profiles}
        alive = list(observed)
        for first in range(0, len(synthetic), max(self.options.workers, 1)):
            chunk = synthetic[first : first + max(self.options.workers, 1)]
            drawn = self.map(lambda r, cs=tuple(alive): self.draw_statistics(current, r, cs, profiles), chunk)
            for draw in drawn:
                for candidate, (*statistics, trace) in draw.items():
                    for kept, statistic in zip(values[candidate], statistics, strict=True):
                        if np.isfinite(statistic):
                            kept.append(max(statistic, 0.0))
                    if trace is not None:
                        traces[candidate].append(trace)
            lower = {c: calibration_scales(observed[c], values[c], len(synthetic)) for c in alive}
            # a profiled form is chosen again after every draw: it stays to the end
            alive = [
                c for c in alive if c in traces or log_p_value(observed[c], *lower[c]) <= math.log(bound)
            ]
            if not alive:
                break
        q = {c: max(observed[c].unknowns, 1) for c in traces}
        profile_scales = {
            c: np.maximum(1.0, np.mean(t, axis=0) / q[c]) if t else None for c, t in traces.items()
        }
        return {c: (*calibration_scales(observed[c], values[c]), profile_scales.get(c)) for c in observed}

    def rescaled(
        self,
        current: FittedModel,
        simulated: Simulated,
        profile: ScaleProfile,
        profile_scales: np.ndarray,
        ratio_scale: float,
    ) -> tuple[CandidateScore, Candidate, tuple[float, float]]:
        """A profiled form tested where its standardised profile Z = T/c is largest (c: T's bootstrap mean per
        scale over q): the score statistic there against Davies' bound with √Z's variation; the simulation's
        likelihood ratio there, with the scale measured at the profile's raw choice."""
        order, variation = profile.ranked(profile_scales)
        for best in order:
            candidate = (profile.form_at(best),)
            score, _, _ = trial(self.reference, current, simulated, candidate)
            if reason := profile.elastic(best):
                score = replace(score, verdict=reason)
            if score.verdict == "tested" or reason:
                break
        wald_scale, statistic = float(profile_scales[best]), float(profile.statistic[best])
        score = replace(
            score, equation_statistic=statistic, search_variation=variation * math.sqrt(wald_scale)
        )
        return score, candidate, (wald_scale, ratio_scale)

    def draw_statistics(
        self,
        current: FittedModel,
        recording: Recording,
        candidates: tuple[Candidate, ...],
        profiles: dict[Candidate, ScaleProfile],
    ) -> dict[Candidate, tuple[float, float, np.ndarray | None]]:
        """Each candidate's Wald and likelihood-ratio statistics on one synthetic recording, as measured (a
        profiled form: its likelihood ratio at the measured choice, and its profile on the measured grid)."""
        on = self.reference.on(recording)
        base = fit(on, current.structure, warm=current)
        (simulated,) = free_simulations([base], recording)
        out: dict[Candidate, tuple[float, float, np.ndarray | None]] = {}
        for c in candidates:
            score = trial(on, base, simulated, c)[0]
            if c in profiles:  # (its Wald statistic is not needed: its profile is standardised instead)
                trace = score_profile(on, base, profiles[c].form, profiles[c].grid_log2).statistic
                out[c] = (math.nan, score.simulation_statistic, trace)
            else:
                out[c] = (score.equation_statistic, score.simulation_statistic, None)
        return out


def gap_words(effects: str, before_m: float, after_m: float) -> str:
    """The conclusion's first half: what was named and how the gap moved (each effect was significant when
    named; together they may not help); a model without a finite gap diverges."""
    if not math.isfinite(after_m) and (not effects or not math.isfinite(before_m)):
        named = f"named {effects}" if effects else "nothing named"
        return f"{named}: the model diverges" + (" before and after" if effects else "")
    before, after = (f"{m * 1e6:.1f} µm" if math.isfinite(m) else "diverged" for m in (before_m, after_m))
    if not effects:
        return f"nothing named: the gap is {after}"
    return f"named {effects}: the gap {'fell' if after_m <= before_m else 'rose'} from {before} to {after}"


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
    if identified:
        if progress is not None:
            progress(DiagnoseProgress(0, "identifying the constants the vehicle file does not state"))
        vehicle = identify_unstated(recording, vehicle, TESTED_RATES, options.points)
    points = options.points or DEFAULT_POINTS[vehicle.model.value]
    reference = Reference.of(recording, vehicle, FitSettings(points, options.nsample), identified)
    result = _Doctor(reference, options, progress, cancel).diagnose()
    result.refit = refined(result, recording, cancel, progress)
    return result


def refined(
    result: DiagnosisResult,
    recording: Recording,
    cancel: threading.Event | None = None,
    progress: Callable[[DiagnoseProgress], object] | None = None,
) -> tuple[IdentifiedModel, float] | None:
    """Step 5's model for prediction: an unexplained final model refined on the free-simulation gap (None
    when explained, or when the final model has a rate fitted below zero, which no model file holds)."""
    if not result.unexplained or result.final_model is None:
        return None
    try:
        start = model_from_json(model_json(result.final_model))
    except ModelFormatError:
        return None
    at = DiagnoseProgress(len(result.steps), "refining the curve on its free-simulation gap")  # the stage
    return refined_on(start, recording, cancel, progress and (lambda p: progress(replace(at, generation=p))))
