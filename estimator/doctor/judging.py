"""How the model doctor judges a round's candidates (estimator.doctor.diagnose, criteria (a)-(f) in its
module text): each candidate's score, the gap reduction and parameter spread it must meet, which one is
chosen, which are strong in the equations, and when a stiffness correction is named at the noise floor.

`Judging` is the judging half of the doctor (`_Doctor` in estimator.doctor.diagnose inherits it): its
methods read the doctor's options, recording and fits from `self`, as they did when they were written in
that class.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from estimator.doctor.catalog import (
    CONFIRMED_SIGNIFICANCE_Z,
    SIGNIFICANCE_Z,
    EffectInstance,
    EffectName,
)
from estimator.doctor.evidence import gather
from estimator.doctor.model import FittedModel, ModelStructure, first_stage, fit
from estimator.doctor.result import CandidateScore
from estimator.doctor.rounds import (
    Candidates,
    Played,
    RoundState,
    Simulated,
    added_unknowns,
    bic_difference,
    heldout_objective,
    plate_centre_m,
)

if TYPE_CHECKING:
    from estimator.doctor.diagnose import DiagnoseOptions


STIFFNESSES = (EffectName.SPRING_STIFFNESS, EffectName.TYRE_STIFFNESS, EffectName.ANTI_ROLL_BAR)
"""The candidates that are a spring the vehicle file states wrong or omits: criterion (a) asks less of their
gap when the equations demand them strongly (Judging.min_gap_reduction)."""


class Judging:
    """The judging half of the model doctor (see the module)."""

    options: DiagnoseOptions

    def strong_in_equations(
        self, instance: EffectInstance, played: Played, reduction: float | None = None
    ) -> bool:
        """The candidate is physically possible, follows the residual, and lowers the objective by at least
        `reduction` (default strong_objective_reduction) on all samples and on the held-out blocks (whatever
        its gap did)."""
        options = self.options
        score = next(s for s in played.scores if s.effect == instance.label)
        model = played.fits.full[instance]
        limit = 1.0 - (options.strong_objective_reduction if reduction is None else reduction)
        return (
            instance in played.outcomes
            and np.isfinite(played.outcomes[instance].gap_m)
            and max(score.objective_ratio, score.heldout_ratio or np.inf) <= limit
            and (score.correlation or 0.0) >= options.min_correlation
            and model.implausible(instance) is None
        )

    def at_the_floor(
        self, state: RoundState, played: Played, expected: float, residual_ratio: float
    ) -> tuple[EffectInstance, float] | None:
        """After the last round, a candidate the equations demand but the gap cannot confirm because the gap
        is mostly what a complete model leaves too (the curve's discretisation): strong in the equations
        (strong_in_equations), with it the objective at most that of the complete models re-identified for the
        expected gap (residual ratio times its objective ratio at most 1: it explains all the equations lack),
        and its gap at or below the expected gap or not above the current model's beyond floor_tie_tolerance
        (the output does not contradict it). Candidates measured against a base of their own
        (coulomb_friction, fits.bases) are not: their objective ratio is not against the current model.
        Independent world (held-out draws, valve dampers, 2 ms or no lift-off): tyre rate ×0.78, ×0.75 and
        spring rate ×0.78 found right (+28.1%, +33.6%, +26.7%) with objective 0.49-0.59 on all samples and
        held out, but the gap moved by -4% to +8%, at the expected 277-364 µm; the final model's residual
        ratio 1.43-1.95. Channel delays of 1.1-3.4 ms found within 2% (objective 0.19-0.49, correlation
        0.90-0.99, residual ratio 1.9-3.1 before, 0.6-1.0 with it) whose gap fell 11-19%, to 0.8-1.35 times
        the expected gap, and one of 1.59 ms (objective 0.43) whose gap rose 0.9%, to 1.05 times it; a
        lift-off of 1.4% with a bump stop named (objective 0.85, gap -5%) and a bump stop with a lift-off
        named (objective 0.73, gap -5%), both at 1.06-1.26 times the expected gap. A candidate that adds no
        unknown (tyre_liftoff) need only be strong by unknown_free_objective_reduction. On clean recordings no
        physically possible candidate was strong in the last round; on recordings with an effect outside the
        catalog the strong ones (delays, bump stops, rates standing in for it) left 1.6-9 times a complete
        model's residual. The candidate and its share of a complete model's objective, or None."""
        if not np.isfinite(expected) or not np.isfinite(residual_ratio) or state.simulated is None:
            return None
        options = self.options
        no_worse_m = state.simulated.gap_m * (1.0 + options.floor_tie_tolerance)

        def reduction(instance: EffectInstance) -> float:
            # a candidate with no unknown of its own (tyre_liftoff) cannot lower the objective by fitting
            free = added_unknowns(state.current, played.fits.full[instance]) == 0
            return options.unknown_free_objective_reduction if free else options.strong_objective_reduction

        shares = {
            i: residual_ratio * played.fits.ratios[i]
            for i in played.fits.kept
            if i not in played.fits.bases
            and self.strong_in_equations(i, played, reduction(i))
            and played.gaps[i] <= max(expected, no_worse_m)
            and residual_ratio * played.fits.ratios[i] <= 1.0
        }
        if not shares:
            return None
        best = min(shares, key=shares.__getitem__)
        return best, shares[best]

    def score(
        self,
        instance: EffectInstance,
        structure: ModelStructure,
        current: FittedModel,
        simulated: Simulated,
        fits: Candidates,
        gap_m: float | None,
        heldout_base: float,
        rows: np.ndarray,
        like: Simulated | None = None,
        first_stage_gap_m: float | None = None,
    ) -> tuple[CandidateScore, bool, bool]:
        """A candidate's score, whether it qualifies to be named (criteria (a)-(f) of the module
        docstring), and whether only with (a) on the gap above the floor (shrinks_above_floor). like: the
        simulated base of a candidate with one (fits.bases): (a)-(c) then compare the candidate with that
        base, and its gap must not exceed the current model's either. first_stage_gap_m: the gap of such a
        candidate's first stage (model.fit: the friction on the friction grid and constraint), which (a)-(c)
        compare with that base; the model named has the curve refitted on the reference grid (gap_m), and it
        is that gap which must not exceed the current model's."""
        ratio, trial = fits.ratios[instance], fits.trials[instance]
        now, model_now = simulated, current
        full, held = fits.full.get(instance), fits.held.get(instance)
        named_gap_m = gap_m
        if like is not None and instance in fits.bases:
            base_full, base_held = fits.bases[instance]
            current, simulated = base_full, like
            heldout_base = heldout_objective(base_held, rows)
            full = None if full is None else first_stage(full)
            held = None if held is None else first_stage(held)
            if first_stage_gap_m is not None:
                gap_m = first_stage_gap_m
        options = self.options
        if full is None or held is None or gap_m is None:
            verdict = f"screened out: the objective falls only {100 * (1 - ratio):.1f}%"
            return (
                CandidateScore(
                    instance.label, ratio, None, None, None, None, None, trial.parameters(instance), verdict
                ),
                False,
                False,
            )
        heldout = heldout_objective(held, rows) / heldout_base
        gap_ratio = (
            gap_m / simulated.gap_m if np.isfinite(simulated.gap_m) else (0.0 if np.isfinite(gap_m) else 1.0)
        )
        bic = bic_difference(simulated, gap_m, added_unknowns(current, full))
        correlation = gather(instance, current, full, self.frequency).correlation
        strong = (
            ratio <= 1.0 - options.strong_objective_reduction
            and gap_ratio <= 1.0 - options.strong_gap_reduction
        )
        reasons = []
        # a candidate this strong on all samples, on held-out data and in the gap is no noise: its
        # standard error (sandwich with a block long-run variance) then mostly measures what the model
        # still lacks, not the noise (independent world, 27 N of friction on a motorcycle that lifts off:
        # 24 N fitted, objective 0.63 and held-out 0.62 of the base's, gap -62%, standard error 10 N)
        waived = strong and heldout <= 1.0 - options.strong_objective_reduction
        confirmed = gap_ratio if np.isfinite(gap_m) else 1.0
        implausible = full.implausible(instance, None if waived else self.significance_z(confirmed))
        if implausible:
            reasons.append(implausible)
        reduction = self.min_gap_reduction(instance, ratio, heldout)
        short_of_a = np.isfinite(gap_m) and gap_ratio > 1.0 - reduction
        if not np.isfinite(gap_m):
            reasons.append("the model with it diverges")
        elif short_of_a:
            reasons.append(
                f"the gap falls only {100 * (1 - gap_ratio):.0f}%"
                if gap_ratio < 1.0
                else "the gap does not fall"
            )
        # like with like, but the output must not contradict it either: a gap above the current model's
        # and above what a complete model of the current structure leaves, beyond what counts as a tie
        # elsewhere (choose, at_the_floor); the floor is computed only when it decides (larger_at)
        larger_at = None
        if simulated is not now and named_gap_m is not None:
            if not np.isfinite(named_gap_m):
                if np.isfinite(gap_m):
                    reasons.append("the model with it diverges")
            elif named_gap_m > now.gap_m * (1.0 + options.tie_tolerance):
                larger_at = len(reasons)
        if heldout > 1.0 - options.min_heldout_reduction:
            reasons.append("no better on held-out data")
        if bic > -options.bic_margin:
            reasons.append("the information criterion does not favour it")
        if correlation < self.min_correlation(confirmed):
            reasons.append(f"the residual does not follow its signal (correlation {correlation:.2f})")
        # (a) on the part of the gap a complete model would not leave, asked only of a candidate that meets
        # every other criterion (the floor costs a few fits)
        above_floor = (
            short_of_a
            and len(reasons) == 1
            and larger_at is None
            and self.shrinks_above_floor(simulated.gap_m, gap_m, reduction, model_now, now)
        )
        if above_floor:
            reasons = []
        if larger_at is not None:
            larger = self.larger_than_current(named_gap_m, model_now, now, decides=not reasons)
            if larger:
                reasons.insert(larger_at, larger)
        spread = None
        if not reasons:
            spread, described = self.parameter_spread(instance, structure, full)
            if spread is not None and spread > options.max_parameter_spread and not strong:
                reasons.append(f"its parameter is not the same over the sweep ({described})")
        verdict = "rejected: " + "; ".join(reasons) if reasons else "qualifies"
        if above_floor and not reasons:
            verdict = "qualifies on the gap above a complete model's"

        score = CandidateScore(
            instance.label,
            ratio,
            heldout,
            gap_m,
            gap_ratio,
            bic,
            correlation,
            full.parameters(instance),
            verdict,
            spread,
        )
        return score, not reasons, bool(above_floor)

    def larger_than_current(
        self, named_gap_m: float, current: FittedModel, simulated: Simulated, decides: bool
    ) -> str | None:
        """Why the gap of the model a candidate with a base of its own would name (named_gap_m, above the
        current model's beyond tie_tolerance) contradicts it, or None when it does not: a gap at or below
        what a complete model of the current structure leaves on this sweep (floor_m, within tie_tolerance)
        is no contradiction, as at_the_floor holds too, since the current model's own gap can fall below
        that floor by chance. decides: the candidate meets every other criterion; only then is the floor
        computed (it costs a few fits). Independent world, held-out friction draws: 43 N of friction after a
        lift-off, refitted gap 135.0 µm against the current 100.2 µm and a floor of 840.9 µm; 115 N on a
        car at 2 ms, 51.4 µm against 45.0 µm and a floor of 54.3 µm (objective 0.69, first-stage gap
        -72%)."""
        larger = (
            f"the gap of the model it would name, {named_gap_m * 1e6:.1f} µm, is larger than the current "
            f"model's {simulated.gap_m * 1e6:.1f} µm"
        )
        if not decides:
            return larger
        floor = self.floor_m(current, simulated)
        if np.isfinite(floor) and named_gap_m <= floor * (1.0 + self.options.tie_tolerance):
            return None
        return f"{larger} and than a complete model's {floor * 1e6:.1f} µm" if np.isfinite(floor) else larger

    def floor_m(self, current: FittedModel, simulated: Simulated) -> float:
        """The gap a model without missing effects leaves on this sweep, for the structure of `current`
        simulated as `simulated` (m; inf or nan when there is none to compare with). The doctor computes it
        (estimator.doctor.expected)."""
        raise NotImplementedError

    def shrinks_above_floor(
        self, before_m: float, gap_m: float, reduction: float, current: FittedModel, simulated: Simulated
    ) -> bool:
        """Criterion (a) on the part of the gap a complete model would not leave: with F the gap a model
        without missing effects leaves for the current structure (floor_m), the excess √(gap² − F²) (the
        curve's discretisation and the noise add to a missing effect's misfit in quadrature) falls from
        before_m's to gap_m's by at least `reduction`; a gap_m at or below F has none left. Where the floor
        is most of the gap, a missing effect cannot shrink the whole gap by a quarter even when found right
        (independent world, pairs of effects, each probed: tyre ×1.29 and a plate lagging 1.72 ms, the delay
        after the tyre rate found 2.1 ms, gap 38.9 → 29.2 µm, -24.9%, floor 32.3 µm; bump stop and spring
        ×1.26 on a motorcycle, the two together 273.1 → 207.1 µm, -24.2%, floor 156.1 µm). False where
        the gap did not fall or there is no floor to compare with."""
        if not (np.isfinite(before_m) and np.isfinite(gap_m)) or gap_m >= before_m:
            return False
        floor = self.floor_m(current, simulated)
        if not np.isfinite(floor):
            return False
        excess_before = np.sqrt(max(before_m**2 - floor**2, 0.0))
        excess_after = np.sqrt(max(gap_m**2 - floor**2, 0.0))
        return bool(excess_before > 0.0 and excess_after <= (1.0 - reduction) * excess_before)

    def min_gap_reduction(self, instance: EffectInstance, ratio: float, heldout: float) -> float:
        """Criterion (a)'s limit: min_gap_reduction, or stiffness_min_gap_reduction for a stiffness whose
        equations improve strongly on all samples and on held-out data. The anti-roll bar is one: a spring
        on the roll deflection that the vehicle file omits. Independent world (car axle with valve dampers,
        1 ms, gap 391 µm, of which a complete model leaves 356 µm): the bar found within 4% (11 986 N/m of
        12 413), objective 0.51 on all samples and held out, gap -22%; a spring rate 37% too stiff stood in
        for it (objective 0.63, gap -11%) and was named."""
        options = self.options
        stiffness = instance.name in STIFFNESSES
        strong = max(ratio, heldout) <= 1.0 - options.strong_objective_reduction
        return options.stiffness_min_gap_reduction if stiffness and strong else options.min_gap_reduction

    def min_correlation(self, gap_ratio: float) -> float:
        """Criterion (e)'s limit: min_correlation, or confirmed_min_correlation when the gap falls by
        min_gap_reduction on its own. The correlation is about the square root of the share of the most
        affected equation's residual the candidate explains, and those residuals carry the noise of twice
        differentiated displacements: a real effect the output confirms can be a small share of them."""
        options = self.options
        if gap_ratio <= 1.0 - options.min_gap_reduction:
            return options.confirmed_min_correlation
        return options.min_correlation

    def significance_z(self, gap_ratio: float) -> float:
        """Criterion (d)'s standard errors: SIGNIFICANCE_Z, or CONFIRMED_SIGNIFICANCE_Z when the gap falls by
        min_gap_reduction on its own (as min_correlation: the output confirms what the equations say)."""
        if gap_ratio <= 1.0 - self.options.min_gap_reduction:
            return CONFIRMED_SIGNIFICANCE_Z
        return SIGNIFICANCE_Z

    def parameter_spread(
        self, instance: EffectInstance, structure: ModelStructure, full: FittedModel
    ) -> tuple[float | None, str]:
        """The effect fitted on the first and on the second half of the sweep: the largest difference of
        its parameters relative to the whole-sweep value (None for an effect without parameters). A real
        effect is the same over the whole sweep; a candidate that only stands in for something else (say a
        resonance the model lacks) fits differently where that something is and where it is not."""
        whole = full.effect_values(instance)
        if not whole:
            return None, ""
        time_s = self.recording.time_s[full.system.sample_index]
        first = time_s < np.median(time_s)

        def half(rows: np.ndarray) -> tuple[dict[str, float], dict[str, float]]:
            model = fit(self.reference, structure.with_effect(instance), rows, warm=full)
            return model.effect_values(instance), model.standard_errors(list(whole), rows)

        (a_values, a_errors), (b_values, b_errors) = self.map(half, (first, ~first))
        spread, described = 0.0, ""
        for name, value in whole.items():
            a, b = a_values[name], b_values[name]
            if name in a_errors and abs(a - b) <= SIGNIFICANCE_Z * np.hypot(a_errors[name], b_errors[name]):
                continue  # the halves do not differ beyond what their own standard errors allow
            relative = abs(a - b) / max(abs(value), 1e-300)
            if relative >= spread:
                spread, described = relative, f"{name} {a:.4g} in the first half, {b:.4g} in the second"
        return spread, described

    def choose(
        self,
        eligible: list[EffectInstance],
        gaps: dict[EffectInstance, float],
        full: dict[EffectInstance, FittedModel],
    ) -> EffectInstance | None:
        """The qualifying candidate with the smallest gap. Candidates whose gaps tie (within tie_tolerance)
        are told apart by the equations: the one whose objective is lowest, as the gap of a simulation
        carries the curve's discretisation and every other missing effect with it (independent world, a
        wrong spring rate on a motorcycle that also lifts off: spring_stiffness objective 0.37, gap
        156.0 µm; progressive_spring 0.58 and 154.8 µm, named first). Those the equations cannot tell apart
        either (an offset of the wheel sensor and the opposite offset of the plate sensor) are told apart
        by the plate."""
        if not eligible:
            return None
        tolerance = 1.0 + self.options.tie_tolerance
        best = min(gaps[i] for i in eligible)
        tied = [i for i in eligible if gaps[i] <= best * tolerance]
        lowest = min(full[i].objective for i in tied)
        alike = [i for i in tied if full[i].objective <= lowest * tolerance]
        return min(alike, key=lambda i: (plate_centre_m(full[i], self.frequency), gaps[i]))
