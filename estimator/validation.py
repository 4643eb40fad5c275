"""Cross-validation of an identified model on another recording of the same vehicle: the model (rebuilt by
estimator.model_io) is driven by the new recording's plate motion (estimator.output_error, the simulation
identify reports its gap with) and its body and wheel motion compared with the measured one.

gap_m: RMS of simulated minus measured over the body and wheel channels (as identify's gap_m);
response_rms_m: RMS of the measured body and wheel motion about their means (the same channels, pooled);
gap_ratio: gap_m / response_rms_m, how much of the motion the model gets wrong (0 = all of it right; the
same vehicle with sensor noise a few µm stays near the noise, another damper leaves a larger share).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.output_error import IdentifiedModel, simulate_identified
from estimator.recording import Recording
from estimator.signals import choose_filters, kinematics


@dataclass(frozen=True)
class ValidationResult:
    gap_m: float
    """inf when the model diverges on this plate motion."""
    response_rms_m: float

    @property
    def gap_ratio(self) -> float:
        return self.gap_m / self.response_rms_m if self.response_rms_m > 0 else math.inf

    def to_json(self) -> dict[str, object]:
        """{gap_m, response_rms_m, gap_ratio, gap_diverged}; a diverged gap and its ratio are null."""
        finite = math.isfinite(self.gap_m)
        return {
            "gap_m": self.gap_m if finite else None,
            "response_rms_m": self.response_rms_m,
            "gap_ratio": self.gap_ratio if finite and math.isfinite(self.gap_ratio) else None,
            "gap_diverged": not finite,
        }


def check_model_fits(model: IdentifiedModel, recording: Recording) -> None:
    """ValueError (one line) when the model is of another kind than the recording's channels."""
    if model.vehicle.is_axle != recording.is_axle:
        has = "axle" if recording.is_axle else "quarter-car"
        kind = "an axle" if model.vehicle.is_axle else "a quarter car"
        raise ValueError(f"the model is for {kind} but the recording has {has} channels")


def validate(model: IdentifiedModel, recording: Recording) -> ValidationResult:
    """Simulate `model` from the recording's plate (its own sample time and length) and compare."""
    check_model_fits(model, recording)
    dt = recording.sample_time_s
    cutoff = choose_filters(recording.channels, dt).kinematics_cutoff_Hz
    kin = {name: kinematics(x, cutoff, dt) for name, x in recording.channels.items()}
    simulated = simulate_identified(model, recording, kin)
    motion = np.stack([x - np.mean(x) for x in simulated.measured.values()])
    return ValidationResult(float(simulated.gap_m), float(np.sqrt(np.mean(motion**2))))
