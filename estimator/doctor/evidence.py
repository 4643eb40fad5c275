"""The evidence for a candidate effect, in numbers and in words: where the residual it explains sits (which
equation or channel, which part of the sweep, which range of velocity or deflection), which signal the
residual follows, and by how much the gap falls."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.doctor.catalog import CATALOG, EffectInstance, EffectName
from estimator.doctor.model import FittedModel
from estimator.doctor.residuals import band_rms

SMALL_VELOCITY_M_S = 0.02
"""Friction shows where the suspension velocity is below this."""
BAND_SHARE = 0.5
"""Bands whose explained residual is at least this share of the largest are named in the evidence."""


@dataclass(frozen=True)
class Evidence:
    """What a candidate explains. correlation: of the current equation residual with the part the candidate
    explains, in the equation where it explains most; bands_Hz: the part of the sweep where it explains
    most (lo, hi); detail: an effect-specific observation in words."""

    equation: str
    correlation: float
    bands_Hz: tuple[float, float]
    grows_to_top: bool
    starts_at_bottom: bool
    detail: str

    def where(self) -> str:
        lo, hi = self.bands_Hz
        if not np.isfinite(lo):
            return "over the whole sweep"
        if self.grows_to_top and not self.starts_at_bottom:
            return f"grows above {lo:g} Hz"
        if self.starts_at_bottom and not self.grows_to_top:
            return f"is largest below {hi:g} Hz"
        if self.starts_at_bottom and self.grows_to_top:
            return "spreads over the whole sweep"
        return f"is largest at {lo:g}-{hi:g} Hz"


def _bands(
    explained: np.ndarray, frequency_Hz: np.ndarray, top_Hz: float
) -> tuple[tuple[float, float], bool, bool]:
    profile = band_rms({"x": explained}, frequency_Hz, top_Hz)
    values = profile.values["x"]
    if not np.any(np.isfinite(values)) or np.nanmax(values) <= 0:
        return (float("nan"), float("nan")), False, False
    strong = np.nonzero(np.nan_to_num(values) >= BAND_SHARE * np.nanmax(values))[0]
    edges = profile.edges_Hz
    last = int(np.nonzero(np.isfinite(values))[0][-1])
    return (float(edges[strong[0]]), float(edges[strong[-1] + 1])), strong[-1] == last, strong[0] == 0


def _detail(
    effect: EffectInstance,
    current: FittedModel,
    candidate: FittedModel,
    explained: np.ndarray,
    frequency_Hz: np.ndarray,
) -> str:
    index = current.system.sample_index
    corners = current.signals.corners
    name = effect.name
    if name is EffectName.COULOMB_FRICTION:
        speed = np.abs(corners[0].velocity_m_s[index])
        slow = speed < SMALL_VELOCITY_M_S
        if np.any(slow) and np.any(~slow):
            ratio = np.sqrt(np.mean(explained[slow] ** 2) / max(np.mean(explained[~slow] ** 2), 1e-30))
            return (
                f"it is {ratio:.1f}x larger where the suspension velocity is below "
                f"{SMALL_VELOCITY_M_S:g} m/s and changes sign with it"
            )
    if name is EffectName.PROGRESSIVE_SPRING:
        deflection = np.abs(corners[0].deflection_m[index])
        edge = float(np.quantile(deflection, 0.75))
        far = deflection > edge
        ratio = np.sqrt(np.mean(explained[far] ** 2) / max(np.mean(explained[~far] ** 2), 1e-30))
        return f"it is {ratio:.1f}x larger beyond ±{edge * 1e3:.1f} mm of suspension deflection"
    if name is EffectName.TYRE_LIFTOFF:
        share = 100.0 * candidate.context().airborne_fraction
        return f"the fitted tyre would pull on the plate {share:.1f}% of the time, where the residual sits"
    if name is EffectName.ANTI_ROLL_BAR:
        return "the left and right wheel residuals it explains have opposite signs"
    if name in (EffectName.SPRING_STIFFNESS, EffectName.TYRE_STIFFNESS):
        which = "spring" if name is EffectName.SPRING_STIFFNESS else "tyre"
        values = candidate.parameters(effect)
        change = float(values["change_percent"])
        return (
            f"the data give a {which} rate of {float(values[f'{which}_stiffness_N_per_m']):.0f} N/m, "
            f"{abs(change):.0f}% {'above' if change > 0 else 'below'} the stated "
            f"{float(values[f'stated_{which}_stiffness_N_per_m']):.0f} N/m"
        )
    if name is EffectName.CHANNEL_DELAY:
        delay = candidate.channel_values[effect]
        return f"{effect.channel} lags the other channels by {delay * 1e3:.2f} ms"
    if name is EffectName.SENSOR_OFFSET:
        channels = current.signals.recording.channels
        fast = np.nan_to_num(frequency_Hz) >= 0.4 * current.system.filters.excitation_top_Hz
        suffix = str(effect.channel)[3:]
        plate = float(np.mean(channels[f"x_r{suffix}"][fast]))
        tyre = float(np.mean((channels[f"x_t{suffix}"] - channels[f"x_r{suffix}"])[fast]))
        fitted = candidate.channel_values[effect] * 1e3
        if str(effect.channel).startswith("x_r"):
            return (
                f"the plate {effect.channel} oscillates about {plate * 1e3:+.2f} mm instead of zero; "
                f"fitted zero error {fitted:+.3f} mm"
            )
        return (
            f"the tyre deflection averages {tyre * 1e3:+.2f} mm over the fast part of the sweep while the "
            f"plate oscillates about {plate * 1e3:+.2f} mm; fitted zero error of {effect.channel} "
            f"{fitted:+.3f} mm"
        )
    return ""


def gather(
    effect: EffectInstance, current: FittedModel, candidate: FittedModel, frequency_Hz: np.ndarray
) -> Evidence:
    """Evidence of `candidate` (the current model plus `effect`) against the current model; frequency_Hz:
    the sweep frequency at every sample of the recording."""
    before = current.residuals()
    explained = before - candidate.residuals()
    equation = int(np.argmax(np.sqrt(np.mean(explained**2, axis=1))))
    r0, dr = before[equation], explained[equation]
    denominator = float(np.sqrt(np.sum(r0**2) * np.sum(dr**2)))
    correlation = float(np.dot(r0, dr) / denominator) if denominator > 0 else 0.0
    index = current.system.sample_index
    top = current.system.filters.excitation_top_Hz
    bands, to_top, from_bottom = _bands(dr, frequency_Hz[index], top)
    return Evidence(
        equation=current.signals.equations[equation],
        correlation=correlation,
        bands_Hz=bands,
        grows_to_top=bool(to_top),
        starts_at_bottom=bool(from_bottom),
        detail=_detail(effect, current, candidate, dr, frequency_Hz),
    )


def sentence(effect: EffectInstance, evidence: Evidence, gap_before_m: float, gap_after_m: float) -> str:
    """The evidence in words, e.g. "the residual of the wheel equation grows above 8 Hz and follows the
    low-passed tyre deflection rate (correlation 0.93); ...; with tyre_viscoelastic the gap falls from
    225.0 µm to 29.3 µm"."""
    signal = CATALOG[effect.name].signal.format(channel=effect.channel)
    parts = [
        f"the residual of the {evidence.equation} equation {evidence.where()} and follows {signal} "
        f"(correlation {evidence.correlation:.2f})"
    ]
    if evidence.detail:
        parts.append(evidence.detail)
    parts.append(
        f"with {effect.label} the gap {'falls' if gap_after_m < gap_before_m else 'goes'} from "
        f"{gap_before_m * 1e6:.1f} µm to {gap_after_m * 1e6:.1f} µm"
        if np.isfinite(gap_before_m)
        else f"with {effect.label} the model no longer diverges: gap {gap_after_m * 1e6:.1f} µm"
    )
    return "; ".join(parts)
