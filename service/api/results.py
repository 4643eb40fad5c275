"""The results of the job kinds as typed API models: what `GET /jobs/{id}` carries once a job succeeded,
in the shape of `shockbench identify --json` and `shockbench diagnose --json`.

The worker stores a result as JSON (service.jobs.context.finite_json: a number that is not finite is
stored as null), so every figure the estimator may fail to compute (a phase shift the sweep never reaches,
a model that diverged) is `float | None` here. The models describe the stored JSON: reading one back and
dumping it gives the same keys and values (tests/service/test_api_contract.py checks it on real results,
and that every key is typed), so typing the API did not change what clients receive. A key the estimator
adds before it is typed here passes through unchanged (`extra="allow"`), never silently dropped.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from estimator.identify import Solver
from estimator.vehicle import TyreModel
from estimator.verdict import VerdictThresholds, judge

MaybeNumber = float | None
"""A figure that is null when the estimator could not compute a finite value."""


class ResultPart(BaseModel):
    """A part of a stored result: keys not typed here pass through unchanged."""

    model_config = ConfigDict(extra="allow")


# ---- identify ----------------------------------------------------------------------------------------------


class TanhParameters(ResultPart):
    """F(v) = c_s·v + kappa·(tanh(mu·v + beta) − tanh(beta)), F in N, v in m/s."""

    c_s: float = Field(description="linear damping (N·s/m)")
    kappa: float = Field(description="tanh amplitude (N)")
    mu: float = Field(description="tanh slope (s/m)")
    beta: float = Field(description="tanh asymmetry (dimensionless)")


class CurveOut(ResultPart):
    """One identified damper curve: its points, and the tanh model fitted to them."""

    corner: str = Field(description="single (quarter car), or left / right (axle)")
    velocity_m_s: list[float] = Field(description="damper velocity of each point (m/s), ascending")
    force_N: list[float] = Field(description="damper force at each point (N)")
    force_N_low: list[float] | None = Field(None, description="95% confidence band, lower edge (N)")
    force_N_high: list[float] | None = Field(None, description="95% confidence band, upper edge (N)")
    tanh: TanhParameters
    tanh_rms_N: MaybeNumber = Field(description="rms of the tanh fit over the points (N)")
    outliers: list[int] = Field(description="0-based indices of the points the robust fit set aside")


class MassesOut(ResultPart):
    sprung: float = Field(description="sprung mass (kg)")
    unsprung: float = Field(description="unsprung mass per wheel (kg)")


class StiffnessOut(ResultPart):
    spring: MaybeNumber = Field(description="spring rate at the wheel (N/m)")
    tyre: MaybeNumber = Field(description="tyre stiffness (N/m)")
    anti_roll_bar: MaybeNumber = Field(None, description="axle: anti-roll bar rate at the wheel (N/m)")
    identified: list[str] = Field(default_factory=list, description="those found from the recording")


Interval = list[float]
"""A 95% confidence interval [low, high] (estimator.uncertainty)."""


class MassesIntervalOut(ResultPart):
    sprung: Interval = Field(description="sprung mass, 95% interval (kg)")
    unsprung: Interval = Field(description="unsprung mass per wheel, 95% interval (kg)")


class StiffnessIntervalOut(ResultPart):
    """95% intervals of the identified stiffnesses only (N/m)."""

    spring: Interval | None = None
    tyre: Interval | None = None
    anti_roll_bar: Interval | None = None


class InspectionOut(ResultPart):
    """The inspection figures of one corner."""

    eusama_percent: MaybeNumber = Field(description="EUSAMA road holding: least contact force / static (%)")
    phase_shift_min_deg: MaybeNumber = Field(description="least phase shift above 6 Hz (degrees)")
    damping_ratio: MaybeNumber = Field(description="damping ratio of the body mode")
    equivalent_damping_Ns_per_m: MaybeNumber = Field(description="linear damping of equal energy (N·s/m)")


class ImbalanceOut(ResultPart):
    eusama_difference_points: MaybeNumber = Field(description="|left − right| EUSAMA (percentage points)")
    damping_difference_percent: MaybeNumber = Field(
        description="left/right equivalent damping difference (%)"
    )


class AxleInspectionOut(ResultPart):
    """The inspection figures of an axle: each side, and how much they differ."""

    left: InspectionOut
    right: InspectionOut
    imbalance: ImbalanceOut | None


class VerdictOut(ResultPart):
    """Pass, check or fail: the lane figures judged against the service's thresholds (estimator.verdict)."""

    outcome: Literal["pass", "check", "fail"]
    thresholds_version: str = Field(description="which thresholds judged it")
    reasons: list[str] = Field(description="one line per figure that made it check or fail")
    thresholds: dict[str, float] = Field(description="the limits themselves (degrees, %)")


def verdict_of(limits: VerdictThresholds) -> Callable[[str, dict[str, Any]], dict[str, Any]]:
    """The job manager's `completing` hook: an identification's result gains the verdict its inspection
    figures earn under `limits`, stored with it (a later change of thresholds does not rewrite it)."""

    def completing(kind: str, result: dict[str, Any]) -> dict[str, Any]:
        inspection = result.get("inspection")
        if kind != "identify" or not isinstance(inspection, dict):
            return result
        return {**result, "verdict": judge(inspection, limits).as_dict()}

    return completing


class FiltersOut(ResultPart):
    kinematics_cutoff_Hz: MaybeNumber = Field(description="low-pass of the derived velocities (Hz)")
    equation_cutoff_Hz: MaybeNumber = Field(description="low-pass of the equations (Hz)")
    noise_floor_m: MaybeNumber = Field(description="estimated sensor noise (m rms)")


class SpringHingeOut(ResultPart):
    knot_m: float = Field(description="suspension deflection where the extra rate starts (m, extension > 0)")
    rate_N_per_m: float = Field(description="extra rate beyond the knot (N/m)")


class ModelEffectsOut(ResultPart):
    """A model's effects beyond the curve, masses and tyre: the doctor's final model's, or a lab rig's frame
    guides that identify fits (absent: not in the model; estimator.model_io's docstring)."""

    coulomb_friction_N: float | None = Field(None, description="sliding friction at every corner (N)")
    stribeck_peak_N: float | None = Field(None, description="static peak above the sliding level (N)")
    stribeck_velocity_m_s: float | None = Field(None, description="over which the peak decays (m/s)")
    presliding_m: float | None = Field(
        None, description="hysteretic (Dahl) friction: the displacement over which it builds up (m)"
    )
    cubic_spring_N_per_m3: float | None = Field(None, description="progressive spring k3 (N/m³)")
    spring_hinges: list[SpringHingeOut] | None = Field(None, description="the spring curve's extra rates")
    tyre_dashpot_Ns_per_m: float | None = Field(None, description="tyre dashpot beside the Maxwell element")
    tyre_liftoff: bool | None = Field(None, description="the tyre can leave the plate")
    guide_body_friction_N: float | None = Field(None, description="a rig's frame guides: on the body (N)")
    guide_wheel_friction_N: float | None = Field(None, description="a rig's frame guides: on the wheel (N)")
    channel_delay_s: dict[str, float] | None = Field(None, description="channel -> how much it lags (s)")
    sensor_offset_m: dict[str, float] | None = Field(None, description="channel -> its zero error (m)")
    sensor_lag_s: dict[str, float] | None = Field(None, description="channel -> first-order lag τ (s)")
    sensor_average_s: dict[str, float] | None = Field(None, description="channel -> averaging window (s)")
    sensor_gain_error: dict[str, float] | None = Field(
        None, description="channel -> scale error ε: it reads (1 + ε)·x"
    )


class IdentifyResult(ResultPart):
    """The result of an identification (`shockbench identify --json`)."""

    curves: list[CurveOut] = Field(description="one curve (quarter car) or left and right (axle)")
    masses_kg: MassesOut
    stiffness_N_per_m: StiffnessOut | None = Field(
        None, description="the stiffnesses the model used: the vehicle file's, or identified (listed)"
    )
    tyre_viscoelastic_coefficient: MaybeNumber = Field(None, description="tyre ϑ (Maxwell tyre)")
    tyre_relaxation_time_s: MaybeNumber = Field(None, description="tyre relaxation time (Maxwell tyre, s)")
    tyre_viscoelastic_identified: bool | None = Field(None, description="ϑ was found from the recording")
    tyre_damping_Ns_per_m: MaybeNumber = Field(description="identified tyre damping (N·s/m)")
    tyre_model: TyreModel
    effects: ModelEffectsOut | None = Field(
        None, description="a lab rig's frame guides' friction (vehicle file: frame_guides = true)"
    )
    objective: MaybeNumber = Field(description="the paper's objective GF at the solution")
    solver: Solver
    certified_gap: MaybeNumber = Field(
        description="relative optimality gap, certified by the exact solver's dual bound (0: optimal)"
    )
    gap_m: MaybeNumber = Field(description="output-error gap (m rms); null when not simulated or diverged")
    gap_diverged: bool = Field(description="the identified model diverged when simulated")
    inspection: InspectionOut | AxleInspectionOut = Field(
        description="quarter car: the corner's figures; axle: left, right and imbalance"
    )
    filters: FiltersOut
    roll_inertia_kg_m2: MaybeNumber = Field(None, description="axle: identified roll inertia (kg·m²)")
    track_m: MaybeNumber = Field(None, description="axle: the wheel track (m), which validate needs")
    refined_gap_m: MaybeNumber = Field(None, description="output-error gap after refinement (option refine)")
    masses_kg_interval: MassesIntervalOut | None = Field(None, description="95% intervals of the masses")
    stiffness_N_per_m_interval: StiffnessIntervalOut | None = Field(
        None, description="95% intervals of the identified stiffnesses"
    )
    tyre_damping_Ns_per_m_interval: Interval | None = Field(
        None, description="95% interval of the tyre damping (N·s/m); null for the spring tyre model"
    )
    roll_inertia_kg_m2_interval: Interval | None = Field(None, description="axle: 95% interval (kg·m²)")
    effects_interval: dict[str, Interval] | None = Field(
        None, description="effect key -> 95% interval (a lab rig's frame guides' friction, N)"
    )
    warnings: list[str] = Field(default_factory=list, description="what the identification warns about")
    verdict: VerdictOut | None = Field(
        None, description="service only: the lane figures judged against its configured thresholds"
    )


# ---- diagnose ----------------------------------------------------------------------------------------------

ParameterValue = float | str
"""A fitted parameter of an effect: a number, or a word (e.g. the channel it applies to)."""


class DiagnosisStepOut(ResultPart):
    """One effect the doctor added to the model."""

    effect: str = Field(description="stable name of the effect, e.g. sensor_offset(x_r)")
    gap_before_m: MaybeNumber = Field(description="output-error gap before adding it (m)")
    gap_after_m: MaybeNumber = Field(description="output-error gap after adding it (m); null: diverged")
    parameters: dict[str, ParameterValue] = Field(
        description="the effect's fitted shape (estimator.doctor.parameters.report): e.g. the spring "
        "curve's rate at static load and extra rates beyond its knots, the friction's sliding and static "
        "levels, a sensor's filter and constants, a gain error"
    )
    evidence: str = Field(description="why, in words")
    p_value: MaybeNumber = Field(None, description="its p-value in the round that named it")


class CandidateOut(ResultPart):
    """How one candidate effect fared in one round (estimator.doctor.criteria)."""

    effect: str
    objective_ratio: MaybeNumber = Field(description="objective with the candidate / without")
    gap_m: MaybeNumber = Field(
        description="output-error gap with it (m); null: diverged, or not simulated (its Wald test's p is "
        "above α already: both tests must reject)"
    )
    gap_ratio: MaybeNumber = Field(
        description="gap with it / without; null: diverged without it, or not simulated"
    )
    equation_statistic: MaybeNumber = Field(None, description="Wald statistic of its unknowns")
    simulation_statistic: MaybeNumber = Field(
        None, description="likelihood ratio of the free simulation; null: not simulated"
    )
    unknowns: int | None = Field(None, description="how many unknowns it adds (degrees of freedom)")
    equation_p: MaybeNumber = Field(None, description="p-value of the equations' Wald test")
    simulation_p: MaybeNumber = Field(None, description="p-value of the simulation's likelihood ratio")
    p_value: MaybeNumber = Field(None, description="the larger of the two: both tests must reject")
    parameters: dict[str, ParameterValue]
    verdict: str = Field(description="named, or why not")
    search_variation: MaybeNumber = Field(
        None,
        description="total variation of √(Wald statistic) along the scale searched (a friction form's "
        "v_s or presliding displacement; Davies' bound turns it into the search's p-value); 0: none searched",
    )


class ModelCurveOut(ResultPart):
    corner: str = Field(description="single (quarter car), or left / right (axle)")
    velocity_m_s: list[float] = Field(description="damper velocity of each point (m/s), ascending")
    force_N: list[float] = Field(description="damper force at each point (N)")


class LocalisationOut(ResultPart):
    """Where the final model's disagreement is largest (estimator.doctor.result.localisation_json)."""

    channel: str = Field(description="the channel whose output error is largest")
    channel_rms_m: MaybeNumber = Field(description="its output-error RMS (m)")
    band_Hz: list[MaybeNumber] | None = Field(description="the band of the sweep where it is largest (Hz)")
    time_s: list[MaybeNumber] = Field(description="the time window where the output error is largest (s)")
    equation: str = Field(description="the equation whose residual is largest")
    equation_rms_N: MaybeNumber = Field(description="its residual RMS (N)")
    equation_band_Hz: list[MaybeNumber] = Field(description="the band where that residual is largest (Hz)")
    velocity_m_s: list[MaybeNumber] | None = Field(description="suspension velocities where it is largest")
    deflection_m: list[MaybeNumber] | None = Field(description="suspension deflections where it is largest")
    white: list[str] = Field(description="channels whose output error is white")


class DiagnosisModelOut(ResultPart):
    """The final model in the form of identify's result, plus its effects: what validate --model takes."""

    curves: list[ModelCurveOut]
    masses_kg: MassesOut
    stiffness_N_per_m: StiffnessOut
    tyre_model: TyreModel
    tyre_damping_Ns_per_m: MaybeNumber = Field(description="C_d of the tyre model (N·s/m)")
    tyre_viscoelastic_coefficient: MaybeNumber = Field(None, description="tyre ϑ (Maxwell tyre)")
    tyre_relaxation_time_s: MaybeNumber = Field(None, description="tyre relaxation time (Maxwell tyre, s)")
    effects: ModelEffectsOut
    roll_inertia_kg_m2: MaybeNumber = Field(None, description="axle: roll inertia (kg·m²)")
    track_m: MaybeNumber = Field(None, description="axle: wheel track (m)")


class DiagnoseResult(ResultPart):
    """The result of a diagnosis (`shockbench diagnose --json`)."""

    gap_before_m: MaybeNumber = Field(description="output-error gap of the starting model (m)")
    steps: list[DiagnosisStepOut] = Field(description="the effects added, in order")
    final_parameters: dict[str, dict[str, ParameterValue]] = Field(
        default_factory=dict,
        description="each effect named, as the final model has it (fitted beside those named after it; a "
        "step's parameters are those of the model it was named in)",
    )
    gap_after_m: MaybeNumber = Field(description="output-error gap of the final model (m)")
    unexplained: bool = Field(
        description="the goodness-of-fit test rejects the final model: p_value < alpha (a false alarm in a "
        "fraction alpha of recordings that hide nothing)"
    )
    conclusion: str = Field(description="the diagnosis in words")
    p_value: MaybeNumber = Field(
        None, description="goodness of fit: chance of a gap this large if the final model were the truth"
    )
    alpha: MaybeNumber = Field(None, description="the test's false-alarm rate (and each round's)")
    where: str | None = Field(None, description="when unexplained: where, in words")
    located: LocalisationOut | None = Field(None, description="when unexplained: where, as numbers")
    starting_effects: list[str]
    final_effects: list[str]
    expected_gap_m: MaybeNumber = Field(
        description="the mean gap of the final model re-identified on bootstrap draws of itself (m)"
    )
    residual_ratio: MaybeNumber
    noise_floor_m: MaybeNumber
    candidates: list[list[CandidateOut]] = Field(description="every candidate's score, per round")
    model: DiagnosisModelOut | None = Field(
        None, description="the final model (identify's form plus its effects), for validate --model"
    )
    model_gap_m: MaybeNumber = Field(
        None, description="the gap of `model` on this recording (m): validate --model gives it"
    )
    model_refined: bool = Field(
        False,
        description="unexplained: `model`'s damper curve and tyre damping refined on the free-simulation gap "
        "(what the model lacks biases the equations' fit); gap_after_m is the final model's before it",
    )


# ---- validate ----------------------------------------------------------------------------------------------


class ValidateResult(ResultPart):
    """The result of a validation (`shockbench validate --json`): the model driven by this recording's
    plate against its measured body and wheel motion."""

    gap_m: MaybeNumber = Field(description="RMS of simulated minus measured body and wheel motion (m)")
    response_rms_m: MaybeNumber = Field(description="RMS of the measured body and wheel motion (m)")
    gap_ratio: MaybeNumber = Field(description="gap_m / response_rms_m; null when the model diverged")
    gap_diverged: bool = Field(description="the model diverged when simulated from this plate motion")
    effects: list[str] = Field(
        default_factory=list, description="the model's effects beyond identify's form, all simulated"
    )
