"""The bookkeeping of the model doctor's rounds (estimator.doctor.diagnose): the candidates' fits, their
simulations, where the diagnosis stands and what a round gave, and the small measures a round is judged
with (the fitting/held-out blocks, the held-out objective, the plate's centre, the change of BIC)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from estimator.doctor.catalog import EffectInstance
from estimator.doctor.columns import restrict
from estimator.doctor.model import FittedModel, ModelStructure
from estimator.doctor.residuals import effective_samples
from estimator.doctor.result import CandidateScore
from estimator.doctor.simulation import BatchOutputError


@dataclass
class Candidates:
    """One round's fits: trials (every candidate, channel effects after one Gauss-Newton step), their
    objective ratios, the ones kept by the screen, those fitted fully and on the fitting blocks only."""

    trials: dict[EffectInstance, FittedModel]
    ratios: dict[EffectInstance, float]
    kept: list[EffectInstance]
    full: dict[EffectInstance, FittedModel]
    held: dict[EffectInstance, FittedModel]
    bases: dict[EffectInstance, tuple[FittedModel, FittedModel]]
    """Candidates compared with a base other than the current model (coulomb_friction: the current
    structure on the friction grid, see _Doctor.like_bases): that base fitted on all samples and on the
    fitting blocks."""


@dataclass
class Simulated:
    gap_m: float
    residual: dict[str, np.ndarray]
    predicted: dict[str, np.ndarray]


@dataclass(frozen=True)
class RoundState:
    """Where the diagnosis stands: the structure so far, its fit on all samples and on the fitting blocks,
    and its simulation (None before the first round)."""

    structure: ModelStructure
    current: FittedModel
    held: FittedModel
    simulated: Simulated | None


@dataclass
class Played:
    """A round's outcome: every candidate's score, those that qualify (criterion (a) on the whole gap),
    the fits, the current model's simulation, each kept candidate's simulation, and the current model's
    held-out objective."""

    scores: list[CandidateScore]
    eligible: list[EffectInstance]
    fits: Candidates
    simulated: Simulated
    outcomes: dict[EffectInstance, Simulated]
    heldout_base: float
    above_floor: list[EffectInstance] = field(default_factory=list)
    """Those that qualify only with criterion (a) on the gap above a complete model's (not in eligible)."""

    @property
    def gaps(self) -> dict[EffectInstance, float]:
        return {i: s.gap_m for i, s in self.outcomes.items()}


def mark_chosen(scores: list[CandidateScore], chosen: EffectInstance, verdict: str) -> list[CandidateScore]:
    return [s if s.effect != chosen.label else replace(s, verdict=verdict) for s in scores]


def simulated_column(batch: BatchOutputError, index: int, gaps: np.ndarray) -> Simulated:
    return Simulated(
        float(gaps[index]),
        batch.column(index),
        {name: p[:, index] for name, p in batch.predicted.items()},
    )


def blocks_of(time_s: np.ndarray, block_s: float) -> np.ndarray:
    """True on the even blocks (fitted), False on the odd ones (held out)."""
    return (np.floor(time_s / block_s).astype(int) % 2) == 0


def heldout_objective(model: FittedModel, fitted_rows: np.ndarray) -> float:
    return float(restrict(model.system, ~fitted_rows).objective(model.theta))


PLATE_CENTRE_FROM = 0.4
"""The plate's centre is its mean where the sweep is above this fraction of its top frequency (many cycles,
so the mean of the sine is close to zero)."""


def plate_centre_m(model: FittedModel, frequency_Hz: np.ndarray) -> float:
    """RMS over the plate channels (as the model corrects them) of the centre the plate oscillates about.
    The plate is driven about the static position, so this is zero unless the plate's zero is off; it
    tells apart candidates that tie in the equations (an offset of the wheel sensor and the opposite offset
    of the plate sensor give the same tyre deflection)."""
    top = model.system.filters.excitation_top_Hz
    fast = np.nan_to_num(frequency_Hz) >= PLATE_CENTRE_FROM * top
    plates = [x for name, x in model.signals.recording.channels.items() if name.startswith("x_r")]
    centres = [float(np.mean(x[fast])) if np.any(fast) else float(np.mean(x)) for x in plates]
    return float(np.sqrt(np.mean(np.square(centres))))


def bic_difference(current: Simulated, gap_m: float, added_unknowns: int) -> float:
    if not np.isfinite(current.gap_m):
        return -np.inf if np.isfinite(gap_m) else np.inf
    if not np.isfinite(gap_m):
        return np.inf
    n_eff = sum(effective_samples(r) for r in current.residual.values())
    return float(n_eff * np.log(gap_m**2 / current.gap_m**2) + added_unknowns * np.log(n_eff))


def added_unknowns(current: FittedModel, candidate: FittedModel) -> int:
    """How many more unknowns (θ and channel parameters) the candidate has than the current model."""
    count = len(candidate.theta) + len(candidate.channel_values)
    return count - len(current.theta) - len(current.channel_values)
