"""Cross-validation of an identified model on another recording of the same vehicle: the model (rebuilt by
estimator.model_io) is driven by the new recording's plate motion (estimator.output_error, the simulation
identify reports its gap with) and its body and wheel motion compared with the measured one.

gap_m: RMS of simulated minus measured over the body and wheel channels (as identify's gap_m);
response_rms_m: RMS of the measured body and wheel motion about their means (the same channels, pooled);
gap_ratio: gap_m / response_rms_m, how much of the motion the model gets wrong (0 = all of it right; the
same vehicle with sensor noise a few µm stays near the noise, another damper leaves a larger share).

A model with effects beyond identify's form (estimator.model_io.ModelWithEffects, the `model` of diagnose
--json) is simulated with all of them: the force effects are in its physics; with channel effects the
recording is first corrected (a delayed channel advanced, an offset subtracted: what the model says the
true motion was), the model driven by the corrected plate, and its motion turned back into what the sensors
would read before it is compared with the recording as measured (as the doctor computes its gap).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimator.errors import InvalidValueError
from estimator.laser_channels import ChannelCorrections
from estimator.model_io import ModelWithEffects
from estimator.output_error import (
    DIVERGED_GAP_M,
    IdentifiedModel,
    refine_on_output_error,
    simulate_identified,
)
from estimator.recording import Recording
from estimator.signals import Kinematics, choose_filters, kinematics
from estimator.solvers.differential_evolution import DEProgress


@dataclass(frozen=True)
class ValidationResult:
    gap_m: float
    """inf when the model diverges on this plate motion."""
    response_rms_m: float
    effects: tuple[str, ...] = ()
    """The effects beyond identify's form that were simulated (estimator.model_io.EFFECT_KEYS)."""

    @property
    def gap_ratio(self) -> float:
        return self.gap_m / self.response_rms_m if self.response_rms_m > 0 else math.inf

    def to_json(self) -> dict[str, object]:
        """{gap_m, response_rms_m, gap_ratio, gap_diverged, effects}; a diverged gap and its ratio are
        null; effects: the model's effects beyond identify's form, all simulated ([] for identify's)."""
        finite = math.isfinite(self.gap_m)
        return {
            "gap_m": self.gap_m if finite else None,
            "response_rms_m": self.response_rms_m,
            "gap_ratio": self.gap_ratio if finite and math.isfinite(self.gap_ratio) else None,
            "gap_diverged": not finite,
            "effects": list(self.effects),
        }


def check_model_fits(model: IdentifiedModel, recording: Recording) -> None:
    """ValueError (one line) when the model is of another kind than the recording's channels."""
    if model.vehicle.is_axle != recording.is_axle:
        has = "axle" if recording.is_axle else "quarter-car"
        kind = "an axle" if model.vehicle.is_axle else "a quarter car"
        raise InvalidValueError(f"the model is for {kind} but the recording has {has} channels")


@dataclass(frozen=True)
class _Driven:
    """What a simulation of the model on a recording starts from: the model's channel corrections and
    effect names, the recording as the corrections say the true motion was, its channels low-passed (the
    kinematics the simulation starts from) and the sensor noise floor (m). The same for every model with
    the same effects (refined_on compares two)."""

    corrections: ChannelCorrections
    effect_names: tuple[str, ...]
    recording: Recording
    kinematics: dict[str, Kinematics]
    noise_m: float


def _driven(model: IdentifiedModel, recording: Recording) -> _Driven:
    effects = model.effects if isinstance(model, ModelWithEffects) else None
    corrections = effects.channel_corrections() if effects is not None else ChannelCorrections()
    dt = recording.sample_time_s
    driven = corrections.apply(recording)  # the true motion as the model's channel effects say
    filters = choose_filters(recording.channels, dt)
    kin = {name: kinematics(x, filters.kinematics_cutoff_Hz, dt) for name, x in driven.channels.items()}
    names = tuple(effects.names) if effects is not None else ()
    return _Driven(corrections, names, driven, kin, filters.noise_floor_m)


def validate(model: IdentifiedModel, recording: Recording) -> ValidationResult:
    """Simulate `model` from the recording's plate (its own sample time and length) and compare."""
    check_model_fits(model, recording)
    return _compared(model, recording, _driven(model, recording))


def _compared(model: IdentifiedModel, recording: Recording, start: _Driven) -> ValidationResult:
    """validate's comparison, from what the simulation starts from (_driven)."""
    simulated = simulate_identified(model, start.recording, start.kinematics, start.noise_m)
    dt = recording.sample_time_s
    residuals = []
    with np.errstate(over="ignore", invalid="ignore"):  # a diverging model is reported as such
        for name, motion in simulated.simulated.items():
            residuals.append(start.corrections.distort(name, motion, dt) - recording.channels[name])
        gap = float(np.sqrt(np.mean(np.stack(residuals) ** 2)))
    if not (math.isfinite(gap) and gap < DIVERGED_GAP_M):
        gap = math.inf
    measured = np.stack([recording.channels[n] - np.mean(recording.channels[n]) for n in simulated.simulated])
    return ValidationResult(gap, float(np.sqrt(np.mean(measured**2))), start.effect_names)


def refined_on(
    model: IdentifiedModel,
    recording: Recording,
    cancel: threading.Event | None = None,
    progress: Callable[[DEProgress], object] | None = None,
) -> tuple[IdentifiedModel, float] | None:
    """The model with its damper curve(s) and tyre damping refined on its free-simulation gap on
    `recording` (estimator.output_error.refine_on_output_error: a short DE within ±15% of each value, the
    model's effects kept) and that model's validate gap (m); None when refining does not lower the gap.
    Why: a fit of the equations is biased by a force the model lacks (it is in their residual and moves the
    motions they are built from), a fit of the simulated motion to the measured one is not by the part of it
    the plate does not cause. A model to predict with: the part that depends on the motion both fits take
    up into the curve, this one more, so the refined curve is no truer a damper curve (docs/method.md).
    InterruptedError when `cancel` is set meanwhile. `progress` hears of every generation: on a model with a
    sharp friction step the refinement's simulations take many Runge-Kutta steps a sample, and minutes."""
    check_model_fits(model, recording)
    start = _driven(model, recording)  # the refined model keeps the effects: the same start
    before = _compared(model, recording, start).gap_m
    driven, kin, noise_m = start.recording, start.kinematics, start.noise_m

    def generation(p: DEProgress) -> None:  # a report, never a request to stop
        if progress is not None:
            progress(p)

    refined, _ = refine_on_output_error(model, driven, kin, noise_m, callback=generation, cancel=cancel)
    if cancel is not None and cancel.is_set():  # the DE stopped early: not a refined model
        raise InterruptedError("refinement cancelled")
    after = _compared(refined, recording, start).gap_m
    return (refined, after) if after < before else None
