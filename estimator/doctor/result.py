"""What a diagnosis returns: the steps taken (effect, fitted parameters, gap before and after, evidence), the
candidates judged at every step, the residual analysis before and after, and the stable JSON shape of
`shockbench diagnose --json`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from estimator.doctor.catalog import FRICTION_UNKNOWNS, EffectName
from estimator.doctor.residuals import Localisation
from estimator.vehicle import TyreModel

if TYPE_CHECKING:
    from estimator.doctor.model import FittedModel


def _finite_or_none(value: float) -> float | None:
    return float(value) if value is not None and np.isfinite(value) else None


def _range(low: float, high: float) -> list[float | None]:
    return [_finite_or_none(low), _finite_or_none(high)]


def localisation_json(located: Localisation | None) -> dict[str, object] | None:
    """Where a model's disagreement is largest, as numbers (Localisation.describe says it in words): the
    channel and its output-error RMS, the band of the sweep and the time window, the equation and its
    band, and the ranges of suspension velocity and deflection whose equation residual is largest; None
    when there is no localisation or the model diverged."""
    if located is None or not np.isfinite(located.gap_m) or not located.channel_rms_m:
        return None
    channel = located.worst_channel()
    equation = max(located.equation_rms_N, key=lambda e: located.equation_rms_N[e])
    ranges: dict[str, list[float | None]] = {}
    for profile, key in zip(located.by_variable[:2], ("velocity_m_s", "deflection_m"), strict=False):
        values = profile.values[equation]
        if np.any(np.isfinite(values)):
            k = int(np.nanargmax(values))
            ranges[key] = _range(profile.edges[k], profile.edges[k + 1])
    has_band = channel in located.output_bands.values
    return {
        "channel": channel,
        "channel_rms_m": _finite_or_none(located.channel_rms_m[channel]),
        "band_Hz": _range(*located.worst_band(located.output_bands, channel)) if has_band else None,
        "time_s": _range(*located.worst_time_s),
        "equation": equation,
        "equation_rms_N": _finite_or_none(located.equation_rms_N[equation]),
        "equation_band_Hz": _range(*located.worst_band(located.equation_bands, equation)),
        "velocity_m_s": ranges.get("velocity_m_s"),
        "deflection_m": ranges.get("deflection_m"),
        "white": sorted(c for c, w in located.whiteness.items() if w.white),
    }


@dataclass(frozen=True)
class CandidateScore:
    """How one candidate fared in one round (estimator.doctor.criteria).

    objective_ratio: the paper's objective with the candidate over without; gap_m, gap_ratio: its free
    simulation's gap and that over the model's without it; equation_statistic, equation_p: the Wald test of
    its unknowns; simulation_statistic, simulation_p: the likelihood ratio of the gap; p_value: the larger of
    the two p-values; unknowns: how many it adds; verdict: "named" or why not.
    """

    effect: str
    objective_ratio: float
    gap_m: float | None
    gap_ratio: float | None
    equation_statistic: float
    simulation_statistic: float
    unknowns: int
    equation_p: float
    simulation_p: float
    p_value: float
    parameters: dict[str, float | str]
    verdict: str

    def to_json(self) -> dict[str, object]:
        return {
            "effect": self.effect,
            "objective_ratio": _finite_or_none(self.objective_ratio),
            "gap_m": _finite_or_none(self.gap_m) if self.gap_m is not None else None,
            "gap_ratio": _finite_or_none(self.gap_ratio) if self.gap_ratio is not None else None,
            "equation_statistic": _finite_or_none(self.equation_statistic),
            "simulation_statistic": _finite_or_none(self.simulation_statistic),
            "unknowns": self.unknowns,
            "equation_p": self.equation_p,
            "simulation_p": self.simulation_p,
            "p_value": self.p_value,
            "parameters": self.parameters,
            "verdict": self.verdict,
        }


@dataclass
class DiagnosisStep:
    """One effect added: its stable name, the channel for channel effects, fitted parameters, the gap
    before and after (m; inf = the model diverged), and the evidence in words."""

    effect: str
    parameters: dict[str, float | str]
    gap_before_m: float
    gap_after_m: float
    evidence: str
    p_value: float
    located_after: Localisation
    predicted_after: dict[str, np.ndarray] = field(repr=False)

    def to_json(self) -> dict[str, object]:
        return {
            "effect": self.effect,
            "gap_before_m": _finite_or_none(self.gap_before_m),
            "gap_after_m": _finite_or_none(self.gap_after_m),
            "parameters": self.parameters,
            "evidence": self.evidence,
            "p_value": self.p_value,
        }


@dataclass
class DiagnosisResult:
    """The whole diagnosis.

    starting_effects / final_effects: the model's effects beyond the vehicle file's constants before and
    after (the tyre option counts: maxwell = tyre_viscoelastic); expected_gap_m: the mean gap of the final
    structure re-identified on bootstrap draws of itself (estimator.doctor.criteria.GoodnessOfFit);
    p_value: the goodness-of-fit test's; unexplained: p_value < alpha;
    where: the localisation of what is left, when unexplained (in words; `located` in to_json: as
    numbers, localisation_json)."""

    starting_effects: list[str]
    final_effects: list[str]
    gap_before_m: float
    gap_after_m: float
    steps: list[DiagnosisStep]
    rounds: list[list[CandidateScore]]
    """Per round of candidates (one per step, plus the last round that named nothing)."""
    unexplained: bool
    conclusion: str
    expected_gap_m: float
    residual_ratio: float
    """The paper's objective of the final model over the bootstrap draws' mean: about 1 when the equations
    hold as well as noise and the curve's resolution allow."""
    p_value: float
    alpha: float
    where: str | None
    noise_floor_m: float
    located_before: Localisation
    measured: dict[str, np.ndarray] = field(repr=False)
    predicted_before: dict[str, np.ndarray] = field(repr=False)
    time_s: np.ndarray = field(repr=False)
    sweep_frequency_Hz: np.ndarray = field(repr=False)
    final_model: FittedModel | None = field(default=None, repr=False)
    """The model after the effects named (None when the diagnosis did not keep it)."""

    @property
    def effects_named(self) -> list[str]:
        return [s.effect for s in self.steps]

    @property
    def located_after(self) -> Localisation:
        return self.steps[-1].located_after if self.steps else self.located_before

    @property
    def predicted_after(self) -> dict[str, np.ndarray]:
        return self.steps[-1].predicted_after if self.steps else self.predicted_before

    def to_json(self) -> dict[str, object]:
        """The stable JSON shape: gap_before_m, steps [{effect, gap_before_m, gap_after_m, parameters,
        evidence}], gap_after_m, unexplained; plus the starting and final effects, the expected gap, the
        conclusion in words, the goodness of fit's p_value and alpha, where (words) and located (numbers,
        when unexplained), every candidate's score per round and `model`: the final model in the form of
        identify --json's (model_json), which `shockbench validate --model` takes."""
        return {
            "gap_before_m": _finite_or_none(self.gap_before_m),
            "steps": [s.to_json() for s in self.steps],
            "gap_after_m": _finite_or_none(self.gap_after_m),
            "unexplained": self.unexplained,
            "conclusion": self.conclusion,
            "starting_effects": self.starting_effects,
            "final_effects": self.final_effects,
            "expected_gap_m": _finite_or_none(self.expected_gap_m),
            "residual_ratio": _finite_or_none(self.residual_ratio),
            "p_value": self.p_value,
            "alpha": self.alpha,
            "where": self.where,
            "located": localisation_json(self.located_after) if self.unexplained else None,
            "noise_floor_m": self.noise_floor_m,
            "candidates": [[c.to_json() for c in round_] for round_ in self.rounds],
            "model": model_json(self.final_model) if self.final_model is not None else None,
        }


def _rate_N_per_m(model: FittedModel, name: str) -> float:
    """A rate as the model has it: the stated one plus the correction a stiffness effect fitted (the
    FittedModel property of that name where it has one), else the vehicle's."""
    value = getattr(model, name, None)
    return float(value if value is not None else getattr(model.vehicle, name))


def model_json(model: FittedModel) -> dict[str, object]:
    """A fitted model of the doctor in the form of identify --json's result (curves, masses_kg,
    stiffness_N_per_m, tyre_model, tyre damping, ϑ and τ, roll inertia and track for an axle) plus `effects`:
    what that form has no key for (estimator.model_io's docstring), so that estimator.model_io rebuilds it
    whole. The tyre: Maxwell when the model has tyre_viscoelastic (a dashpot beside it is an effect),
    Kelvin-Voigt when it has only the dashpot, a spring otherwise."""
    vehicle = model.vehicle
    axle = vehicle.is_axle
    corners = ["left", "right"] if axle else ["single"]
    maxwell = model.structure.has(EffectName.TYRE_VISCOELASTIC)
    dashpot = model.value("tyre_dashpot_Ns_per_m")
    if maxwell:
        tyre, damping = TyreModel.MAXWELL, model.maxwell_damping_Ns_per_m
    elif dashpot:
        tyre, damping, dashpot = TyreModel.KELVIN_VOIGT, dashpot, 0.0
    else:
        tyre, damping = TyreModel.SPRING, 0.0
    effects: dict[str, object] = {}
    for key, value in (
        ("coulomb_friction_N", model.value(FRICTION_UNKNOWNS[0])),
        ("tyre_dashpot_Ns_per_m", dashpot),
    ):
        if value:
            effects[key] = value
    if model.value(FRICTION_UNKNOWNS[1]):
        effects["stribeck_peak_N"] = model.value(FRICTION_UNKNOWNS[1])
        effects["stribeck_velocity_m_s"] = model.stribeck_velocity_m_s
    hinges = [
        {"knot_m": float(k), "rate_N_per_m": float(r)}
        for k, r in zip(model.knots_m, model.hinge_rates_N_per_m, strict=True)
        if r
    ]
    if hinges:
        effects["spring_hinges"] = hinges
    if model.structure.has(EffectName.TYRE_LIFTOFF):
        effects["tyre_liftoff"] = True
    corrections = model.corrections
    for key, table in (
        ("channel_delay_s", corrections.delay_s),
        ("sensor_offset_m", corrections.offset_m),
        ("sensor_lag_s", corrections.lag_s),
        ("sensor_average_s", corrections.average_s),
        ("sensor_gain_error", corrections.gain_error),
    ):
        if any(table.values()):
            effects[key] = {channel: value for channel, value in table.items() if value}
    stiffness: dict[str, object] = {
        "spring": _rate_N_per_m(model, "spring_stiffness_N_per_m"),
        "tyre": _rate_N_per_m(model, "tyre_stiffness_N_per_m"),
        # the rates the doctor found the stated ones contradict (families spring_curve, tyre_stiffness)
        "identified": [
            n
            for n, family in (("spring", "spring_curve"), ("tyre", "tyre_stiffness"))
            if family in model.structure.labels
        ],
    }
    out: dict[str, object] = {
        "curves": [
            {"corner": corner, "velocity_m_s": curve.velocity_m_s.tolist(), "force_N": curve.force_N.tolist()}
            for corner, curve in zip(corners, model.curves, strict=True)
        ],
        "masses_kg": {
            "sprung": model.sprung_mass_kg,
            "unsprung": vehicle.unsprung_mass_kg(model.sprung_mass_kg),
        },
        "stiffness_N_per_m": stiffness,
        "tyre_model": tyre.value,
        "tyre_damping_Ns_per_m": float(damping),
        "tyre_viscoelastic_coefficient": vehicle.tyre_viscoelastic_coefficient if maxwell else None,
        "tyre_relaxation_time_s": vehicle.tyre_relaxation_time_s if maxwell else None,
        "effects": effects,
    }
    if axle:
        bar = vehicle.anti_roll_bar_stiffness_N_per_m + model.value("anti_roll_bar_N_per_m")
        stiffness["anti_roll_bar"] = bar
        out["roll_inertia_kg_m2"] = model.roll_inertia_kg_m2
        out["track_m"] = vehicle.track_m
    return out
