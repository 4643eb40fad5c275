"""What a diagnosis returns, and its stable JSON shape (`shockbench diagnose --json`)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

import numpy as np

from estimator.doctor.catalog import FRICTION_UNKNOWNS, GUIDE_FRICTION_NAMES, EffectName, labels_in
from estimator.doctor.parameters import report
from estimator.doctor.residuals import Localisation
from estimator.model_io import with_curves_of
from estimator.vehicle import TyreModel

if TYPE_CHECKING:
    from estimator.doctor.model import FittedModel
    from estimator.output_error import IdentifiedModel


def _finite_or_none(value: float | None) -> float | None:
    return float(value) if value is not None and np.isfinite(value) else None


def _json(item: Any, finite: tuple[str, ...], count: int | None = None) -> dict[str, object]:
    """The first `count` fields of a dataclass by name, those in `finite` as _finite_or_none has them."""
    values = ((f.name, getattr(item, f.name)) for f in fields(item)[:count])
    return {name: _finite_or_none(value) if name in finite else value for name, value in values}


def _range(low: float, high: float) -> list[float | None]:
    return [_finite_or_none(low), _finite_or_none(high)]


def localisation_json(located: Localisation | None) -> dict[str, object] | None:
    """Localisation.describe as numbers; None without a localisation or when the model diverged."""
    if located is None or not np.isfinite(located.gap_m) or not located.channel_rms_m:
        return None
    channel = located.worst_channel()
    equation = max(located.equation_rms_N, key=lambda e: located.equation_rms_N[e])
    velocity, deflection = (p.worst(equation) for p in located.by_variable[:2])
    has_band = channel in located.output_bands.values
    return {
        "channel": channel,
        "channel_rms_m": _finite_or_none(located.channel_rms_m[channel]),
        "band_Hz": _range(*located.output_bands.worst(channel)) if has_band else None,
        "time_s": _range(*located.worst_time_s),
        "equation": equation,
        "equation_rms_N": _finite_or_none(located.equation_rms_N[equation]),
        "equation_band_Hz": _range(*located.equation_bands.worst(equation)),
        "velocity_m_s": _range(*velocity) if np.isfinite(velocity[0]) else None,
        "deflection_m": _range(*deflection) if np.isfinite(deflection[0]) else None,
        "white": sorted(located.white),
    }


@dataclass(frozen=True)
class CandidateScore:
    """One candidate in one round (estimator.doctor.criteria): objective and gap with it over without, the
    Wald test of its unknowns (equation_), the likelihood ratio of the gap (simulation_), the larger p."""

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
    search_variation: float = 0.0
    """Total variation of √W along the scale searched (criteria.ScaleSearch; 0: none searched)."""

    def to_json(self) -> dict[str, object]:
        finite = ("objective_ratio", "gap_m", "gap_ratio", "equation_statistic", "simulation_statistic")
        return _json(self, finite)


@dataclass
class DiagnosisStep:
    """One effect added: its label, the gap before and after (m; inf: the model diverged), its fitted
    parameters and the evidence in words."""

    effect: str
    gap_before_m: float
    gap_after_m: float
    parameters: dict[str, float | str]
    evidence: str
    p_value: float
    located_after: Localisation
    predicted_after: dict[str, np.ndarray] = field(repr=False)

    def to_json(self) -> dict[str, object]:
        return _json(self, ("gap_before_m", "gap_after_m"), 6)


@dataclass
class DiagnosisResult:
    """The whole diagnosis: expected_gap_m, the mean gap of the final structure re-identified on its bootstrap
    draws, p_value the goodness-of-fit test's (criteria.GoodnessOfFit); where: what is left, in words."""

    starting_effects: list[str]
    final_effects: list[str]
    gap_before_m: float
    gap_after_m: float
    steps: list[DiagnosisStep]
    rounds: list[list[CandidateScore]]  # one per step, and the last round, which named nothing
    unexplained: bool
    conclusion: str
    expected_gap_m: float
    residual_ratio: float  # the final model's objective over the bootstrap draws' mean
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
    refit: tuple[IdentifiedModel, float] | None = field(default=None, repr=False)  # unexplained: refined_on's

    @property
    def effects_named(self) -> list[str]:
        return [name for s in self.steps for name in labels_in(s.effect)]

    @property
    def final_parameters(self) -> dict[str, dict[str, float | str]]:
        """Each family named as the final model has it, fitted beside the others (a step's: as named)."""
        named, model = set(self.effects_named), self.final_model
        effects = model.structure.effects if model else ()
        return {e.label: report(e, model) for e in effects if e.label in named}  # type: ignore[arg-type]

    @property
    def located_after(self) -> Localisation:
        return self.steps[-1].located_after if self.steps else self.located_before

    @property
    def predicted_after(self) -> dict[str, np.ndarray]:
        return self.steps[-1].predicted_after if self.steps else self.predicted_before

    def to_json(self) -> dict[str, object]:
        """The stable JSON shape; `model` is the final model as identify --json has it (model_json), refined
        when unexplained (refit), which `shockbench validate --model` takes: its gap here is model_gap_m."""
        model = model_json(self.final_model) if self.final_model is not None else None
        return {
            "gap_before_m": _finite_or_none(self.gap_before_m),
            "steps": [s.to_json() for s in self.steps],
            "final_parameters": self.final_parameters,
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
            "model": with_curves_of(model, self.refit[0]) if model and self.refit else model,
            "model_gap_m": _finite_or_none(self.refit[1] if self.refit else self.gap_after_m),
            "model_refined": self.refit is not None,
        }


def model_json(model: FittedModel) -> dict[str, object]:
    """A fitted model as identify --json has it plus `effects` (what that form has no key for), which
    estimator.model_io rebuilds whole. The tyre: Maxwell with tyre_viscoelastic (a dashpot beside it is an
    effect), Kelvin-Voigt with only the dashpot, a spring otherwise."""
    vehicle, structure, corrections = model.vehicle, model.structure, model.corrections
    maxwell, sprung = structure.has(EffectName.TYRE_VISCOELASTIC), model.sprung_mass_kg
    dashpot = model.value("tyre_dashpot_Ns_per_m")
    if maxwell:
        tyre, damping = TyreModel.MAXWELL, model.value("maxwell_damping_Ns_per_m")
    elif dashpot:
        tyre, damping, dashpot = TyreModel.KELVIN_VOIGT, dashpot, 0.0
    else:
        tyre, damping = TyreModel.SPRING, 0.0
    friction, peak = (model.value(n) for n in FRICTION_UNKNOWNS)
    hinges = zip(model.knots_m, model.hinge_rates_N_per_m, strict=True)
    effects: dict[str, object] = {
        "coulomb_friction_N": friction,
        "tyre_dashpot_Ns_per_m": dashpot,
        "stribeck_peak_N": peak,
        "stribeck_velocity_m_s": model.stribeck_velocity_m_s if peak else 0.0,
        "presliding_m": model.presliding_m,
        "spring_hinges": [{"knot_m": float(k), "rate_N_per_m": float(r)} for k, r in hinges if r],
        "tyre_liftoff": structure.has(EffectName.TYRE_LIFTOFF),
        **{name: model.value(name) for name in GUIDE_FRICTION_NAMES},
    }
    tables = ("channel_delay_s", "sensor_offset_m", "sensor_lag_s", "sensor_average_s", "sensor_gain_error")
    for key, table in zip(tables, fields(corrections), strict=True):
        effects[key] = {channel: v for channel, v in getattr(corrections, table.name).items() if v}
    stiffness: dict[str, object] = {
        "spring": model.spring_stiffness_N_per_m,
        "tyre": model.tyre_stiffness_N_per_m,
        # the rates the doctor found the stated ones contradict
        "identified": [
            n for n, f in (("spring", "spring_curve"), ("tyre", "tyre_stiffness")) if f in structure.labels
        ],
    }
    out: dict[str, object] = {
        "curves": [
            {"corner": corner, "velocity_m_s": curve.velocity_m_s.tolist(), "force_N": curve.force_N.tolist()}
            for corner, curve in zip(
                ["left", "right"] if vehicle.is_axle else ["single"], model.curves, strict=True
            )
        ],
        "masses_kg": {"sprung": sprung, "unsprung": vehicle.unsprung_mass_kg(sprung)},
        "stiffness_N_per_m": stiffness,
        "tyre_model": tyre.value,
        "tyre_damping_Ns_per_m": float(damping),
        "tyre_viscoelastic_coefficient": vehicle.tyre_viscoelastic_coefficient if maxwell else None,
        "tyre_relaxation_time_s": vehicle.tyre_relaxation_time_s if maxwell else None,
        "effects": {key: value for key, value in effects.items() if value},
    }
    if vehicle.is_axle:
        stiffness["anti_roll_bar"] = vehicle.anti_roll_bar_stiffness_N_per_m + model.value(
            "anti_roll_bar_N_per_m"
        )
        out["roll_inertia_kg_m2"] = model.roll_inertia_kg_m2
        out["track_m"] = vehicle.track_m
    return out
