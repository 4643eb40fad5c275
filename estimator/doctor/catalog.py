"""The catalogue of effect families, each a named extension of the model with a bounded number of unknowns
(the names `shockbench diagnose --json` prints). A force family's unknowns enter the equations of motion
linearly, a column each (its force filtered by the equations' own low-pass, estimator.equations, so that
they still hold exactly), fitted by the exact solver with the damper curve; channel families correct a
sensor channel before the equations are built, by Gauss-Newton (estimator.doctor.fitting)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum
from functools import cached_property

import numpy as np

from estimator.digital_filters import first_order_filter
from estimator.equations import LinearResiduals
from estimator.frame_guides import GUIDE_FRICTION_NAMES, guide_columns
from estimator.friction import coulomb_sign, friction_force_N, hysteresis_interval_mean, interval_mean
from estimator.recording import Recording
from estimator.signals import lowpass
from estimator.vehicle import VehicleConstant, VehicleParameters


class EffectName(StrEnum):
    TYRE_DAMPING = "tyre_damping"
    TYRE_VISCOELASTIC = "tyre_viscoelastic"
    LOW_SPEED_FRICTION = "low_speed_friction"
    TYRE_LIFTOFF = "tyre_liftoff"
    SPRING_CURVE = "spring_curve"
    ANTI_ROLL_BAR = "anti_roll_bar"
    SENSOR_DYNAMICS = "sensor_dynamics"
    SENSOR_GAIN = "sensor_gain"
    SENSOR_OFFSET = "sensor_offset"
    TYRE_STIFFNESS = "tyre_stiffness"
    GUIDE_FRICTION = "guide_friction"


@dataclass(frozen=True, order=True)
class EffectInstance:
    """A family as added to a model: channel families name their channel, sensor_dynamics its variant ("lag",
    "average"), low_speed_friction its form with its fitted scale, the Stribeck velocity ("5 mm/s") or the
    presliding displacement ("presliding 0.1 mm"; before the fit the form only: STRIBECK, HYSTERETIC)."""

    name: EffectName
    channel: str | None = None
    variant: str | None = None

    @property
    def label(self) -> str:
        inside = ", ".join(x for x in (self.channel, self.variant) if x)
        return f"{self.name.value}({inside})" if inside else self.name.value


HINGE_FRACTIONS = (0.4, 0.7)
"""spring_curve's hinge knots: these fractions of the largest deflection (0.1% / 99.9% quantile) each way."""
STRIBECK, HYSTERETIC = "stribeck", "hysteretic"
"""low_speed_friction's two forms, their scale searched on the recording (fitting.score_profile, within
scale_range): a static peak decaying over the velocity v_s (exp(−(v/v_s)²)), or a reversed friction built up
over the presliding displacement z (Dahl's state, estimator.friction)."""
PRESLIDING = "presliding "

FRICTION_UNKNOWNS = ("friction_sliding_N", "friction_static_excess_N")
SPRING_RATE_UNKNOWN = "spring_rate_change_N_per_m"
TYRE_RATE_UNKNOWN = "tyre_stiffness_change_N_per_m"
CHANNEL_PARAMETERS = {
    (EffectName.SENSOR_DYNAMICS, "lag"): ("delay", "lag"),
    (EffectName.SENSOR_DYNAMICS, "average"): ("delay", "average"),
    (EffectName.SENSOR_GAIN, None): ("gain",),
    (EffectName.SENSOR_OFFSET, None): ("offset",),
}
"""The Gauss-Newton parameters (kinds of estimator.doctor.model.corrections_of) of each channel family."""


Candidate = tuple[EffectInstance, ...]
"""What a round tests (estimator.doctor.diagnose): one family, or a load path's families together."""
LOAD_PATH = (EffectName.SPRING_CURVE, EffectName.TYRE_STIFFNESS)
"""The rates in series between body and plate, also tested together: with both stated wrong, either correction
alone can move the resonances the wrong way (its simulation worse, or a spring curve that is not monotone)."""


JOIN = " + "
"""Between the labels of families named together ("spring_curve + tyre_stiffness")."""


def label(candidate: Candidate) -> str:
    return JOIN.join(e.label for e in candidate)


def labels_in(step_label: str) -> list[str]:
    """The family labels of a step's or candidate's label (label's inverse)."""
    return step_label.split(JOIN)


def members(candidate: Candidate, names: list[str], before: list[str]) -> dict[str, list[int]]:
    """The indices in `names` of each load-path family's unknowns: spring_…, tyre_… not in `before`."""
    prefix = {EffectName.SPRING_CURVE: "spring_", EffectName.TYRE_STIFFNESS: TYRE_RATE_UNKNOWN}
    old = set(before)
    new = [(k, n) for k, n in enumerate(names) if n not in old]
    return {e.label: [k for k, n in new if n.startswith(prefix[e.name])] for e in candidate}


def round_candidates(singles: list[EffectInstance]) -> list[Candidate]:
    """Each family alone, and the load path's together when the model lacks all of them."""
    together = tuple(e for name in LOAD_PATH for e in singles if e.name is name)
    return [(e,) for e in singles] + ([together] if len(together) == len(LOAD_PATH) else [])


@dataclass(frozen=True)
class Corner:
    """One corner's signals (m, m/s): deflection ζ = x_s − x_t and its rate (kinematics low-pass), ζ and tyre
    deflection δ = x_t − x_r as measured (the spring terms), δ low-passed (lift-off) and its rate."""

    deflection_m: np.ndarray
    velocity_m_s: np.ndarray
    spring_deflection_m: np.ndarray
    tyre_deflection_m: np.ndarray
    tyre_deflection_smooth_m: np.ndarray
    tyre_rate_m_s: np.ndarray


class EquationSignals:
    """Signals of one recording (as corrected for the model's channel errors) and the system built on it."""

    def __init__(self, recording: Recording, vehicle: VehicleParameters, system: LinearResiduals) -> None:
        self.recording, self.vehicle, self.system = recording, vehicle, system
        self.sample_time_s = recording.sample_time_s
        kin, raw = system.kinematics, recording.channels
        self.corners: list[Corner] = []
        for suffix in ("_l", "_r") if vehicle.is_axle else ("",):
            body, wheel, plate = kin[f"x_s{suffix}"], kin[f"x_t{suffix}"], kin[f"x_r{suffix}"]
            self.corners.append(
                Corner(
                    deflection_m=body.position_m - wheel.position_m,
                    velocity_m_s=body.velocity_m_s - wheel.velocity_m_s,
                    spring_deflection_m=raw[f"x_s{suffix}"] - raw[f"x_t{suffix}"],
                    tyre_deflection_m=raw[f"x_t{suffix}"] - raw[f"x_r{suffix}"],
                    tyre_deflection_smooth_m=wheel.position_m - plate.position_m,
                    tyre_rate_m_s=wheel.velocity_m_s - plate.velocity_m_s,
                )
            )

    @cached_property
    def sliding_column(self) -> np.ndarray:
        """A force step at zero suspension velocity (low_speed_friction's sliding level), as a column."""
        return self.suspension_column([interval_mean(coulomb_sign, c.velocity_m_s) for c in self.corners])

    @property
    def equations(self) -> tuple[str, ...]:
        return ("left wheel", "right wheel", "heave", "roll") if self.vehicle.is_axle else ("body", "wheel")

    def eq(self, series: np.ndarray) -> np.ndarray:
        """The equation low-pass of a full-length series, at the system's selected samples."""
        filtered = lowpass(series, self.system.filters.equation_cutoff_Hz, self.sample_time_s)
        return filtered[self.system.sample_index]

    def maxwell_regressor(self, rate_m_s: np.ndarray) -> np.ndarray:
        """g with f_v = C_d·g for the Maxwell element τ·ḟ_v + f_v = C_d·δ̇, τ = Δt·ϑ/(1−ϑ), by the bilinear
        transform, not the paper's backward Euler (eq 4): it matches the continuous element simulated."""
        dt = self.sample_time_s
        tau = self.vehicle.maxwell_time_constant_s(dt)
        pole, gain = (2.0 * tau - dt) / (2.0 * tau + dt), dt / (2.0 * tau + dt)
        return first_order_filter((gain, gain), -pole, rate_m_s)

    def suspension_column(self, per_corner: list[np.ndarray]) -> np.ndarray:
        """(equations, samples) column of a force in each suspension, like the damper (a series a corner)."""
        parts = [self.eq(series) for series in per_corner]
        if not self.vehicle.is_axle:
            return np.stack([parts[0], -parts[0]])
        left, right = parts
        return np.stack([-left, -right, left + right, left - right])

    def tyre_column(self, per_corner: list[np.ndarray]) -> np.ndarray:
        """(equations, samples) column of a force in each tyre (in its wheel equation, beside K_t·δ)."""
        parts = [self.eq(series) for series in per_corner]
        zero = np.zeros_like(parts[0])
        return np.stack([parts[0], parts[1], zero, zero] if self.vehicle.is_axle else [zero, parts[0]])


def with_columns(
    system: LinearResiduals, columns: dict[str, np.ndarray], offset: np.ndarray
) -> LinearResiduals:
    """The system with extra unknowns appended (each column (equations, samples)) and a new offset."""
    matrix = system.matrix
    if columns:
        matrix = np.concatenate([matrix, np.stack(list(columns.values()), axis=2)], axis=2)
    names = [*system.parameter_names, *columns]
    return replace(system, matrix=matrix, offset=offset, parameter_names=names, tyre_theta=None, _flat=None)


def stribeck_velocity_m_s(effect: EffectInstance) -> float:
    """v_s of a low_speed_friction variant ("5 mm/s"; 0 for a hysteretic one)."""
    variant = str(effect.variant)
    return float(variant.removesuffix(" mm/s")) / 1000.0 if variant.endswith(" mm/s") else 0.0


def presliding_m(effect: EffectInstance) -> float:
    """z of a hysteretic low_speed_friction variant ("presliding 0.1 mm"; 0 for a Stribeck one)."""
    variant = str(effect.variant)
    return float(variant.removeprefix(PRESLIDING)[:-3]) / 1000.0 if variant.startswith(PRESLIDING) else 0.0


def unscaled(effect: EffectInstance) -> bool:
    """A low_speed_friction form whose scale is still to be fitted."""
    return effect.variant in (STRIBECK, HYSTERETIC)


def with_scale(effect: EffectInstance, scale: float) -> EffectInstance:
    """The form with its scale (m/s or m; three significant digits, as the label reports it)."""
    prefix, unit = ("", " mm/s") if effect.variant == STRIBECK else (PRESLIDING, " mm")
    return replace(effect, variant=f"{prefix}{scale * 1e3:.3g}{unit}")


def scale_range(effect: EffectInstance, corners: list[Corner]) -> tuple[float, float]:
    """The scales (m/s or m) between which a form's shape changes on this recording. A Stribeck peak
    narrower than the velocity's smallest change over a sample at a zero crossing lies within one sample at
    every reversal, whatever its v_s; one as wide as the velocities measured is a force step with a slope,
    which the curve has. A presliding displacement under one sample's median travel reverses within about
    a sample (the Stribeck form's step); one beyond half the deflection's travel never saturates (a spring).
    Extremes as the 0.1% / 99.9% quantiles (hinge_knots_m's)."""
    if effect.variant == STRIBECK:
        series = [c.velocity_m_s for c in corners]
        steps = np.concatenate([np.abs(np.diff(v))[np.signbit(v[1:]) != np.signbit(v[:-1])] for v in series])
        low = float(np.min(steps[steps > 0.0], initial=np.inf))
    else:
        series = [c.deflection_m for c in corners]
        low = float(np.median(np.concatenate([np.abs(np.diff(z)) for z in series])))
    extremes = np.quantile(np.concatenate(series), [0.001, 0.999])
    high = float(np.max(np.abs(extremes)) if effect.variant == STRIBECK else np.ptp(extremes) / 2.0)
    return min(low, high / 2.0), high  # (no reversal: one octave below the extremes)


def hinge_knots_m(recording: Recording, vehicle: VehicleParameters) -> tuple[float, ...]:
    """spring_curve's hinge knots (m of suspension deflection ζ = x_s − x_t, extension positive)."""
    c, suffixes = recording.channels, (("_l", "_r") if vehicle.is_axle else ("",))
    deflection = np.concatenate([c[f"x_s{s}"] - c[f"x_t{s}"] for s in suffixes])
    high, low = float(np.quantile(deflection, 0.999)), float(np.quantile(deflection, 0.001))
    return tuple(f * low for f in reversed(HINGE_FRACTIONS)) + tuple(f * high for f in HINGE_FRACTIONS)


def hinge(deflection_m: np.ndarray, knot_m: float) -> np.ndarray:
    """ζ − knot beyond the knot on its side (above a knot ≥ 0, below one < 0), else 0: what a hinge's
    rate acts on (as estimator.dynamics.CornerPhysics has it)."""
    beyond = deflection_m > knot_m if knot_m >= 0.0 else deflection_m < knot_m
    return np.where(beyond, deflection_m - knot_m, 0.0)


def hinge_unknowns(knots_m: tuple[float, ...]) -> list[str]:
    return [f"spring_hinge_{k}_N_per_m" for k in range(len(knots_m))]


@dataclass(frozen=True)
class Effect:
    """One family: summary, what it is physically; signature, what a model lacking it leaves in residuals."""

    name: EffectName
    summary: str
    signature: str

    def instances(
        self,
        vehicle: VehicleParameters,
        recording: Recording,
        identified: frozenset[VehicleConstant] = frozenset(),
    ) -> list[EffectInstance]:
        """The ways this family can be added to a model (identified: constants found from this recording,
        which cannot contradict it)."""
        if self.name is EffectName.TYRE_STIFFNESS:
            return [] if VehicleConstant.TYRE in identified else [EffectInstance(self.name)]
        if self.name is EffectName.ANTI_ROLL_BAR:
            known = vehicle.anti_roll_bar_stiffness_N_per_m > 0
            return [EffectInstance(self.name)] if vehicle.is_axle and not known else []
        if self.name is EffectName.LOW_SPEED_FRICTION:
            return [EffectInstance(self.name, None, v) for v in (STRIBECK, HYSTERETIC)]
        if self.name is EffectName.GUIDE_FRICTION:  # only a rig whose masses ride on a frame's guides
            return [EffectInstance(self.name)] if vehicle.frame_guides else []
        if not any(self.name is n for n, _ in CHANNEL_PARAMETERS):  # a force family
            return [EffectInstance(self.name)]
        names = sorted(recording.channels)
        if self.name is EffectName.SENSOR_OFFSET:
            # a body channel's zero error only shifts the damper curve: neither residuals nor gap change
            names = [n for n in names if not n.startswith("x_s")]
        variants = ("lag", "average") if self.name is EffectName.SENSOR_DYNAMICS else (None,)
        return [EffectInstance(self.name, n, v) for n in names for v in variants]

    def columns(
        self,
        effect: EffectInstance,
        signals: EquationSignals,
        airborne: list[np.ndarray],
        knots_m: tuple[float, ...],
        identified: frozenset[VehicleConstant],
    ) -> dict[str, np.ndarray]:
        """Unknown name -> (equations, samples) column of a force family; airborne: per corner, where the
        tyre is off the plate (no tyre force)."""
        corners = signals.corners
        contact = [(c, 1.0 - a) for c, a in zip(corners, airborne, strict=True)] if airborne else []
        if self.name is EffectName.TYRE_DAMPING:
            return {"tyre_dashpot_Ns_per_m": signals.tyre_column([c.tyre_rate_m_s * k for c, k in contact])}
        if self.name is EffectName.TYRE_VISCOELASTIC:
            # off the plate nothing drives the element: it relaxes, and lands with what is left of its force
            series = [signals.maxwell_regressor(c.tyre_rate_m_s * k) * k for c, k in contact]
            return {"maxwell_damping_Ns_per_m": signals.tyre_column(series)}
        if self.name is EffectName.LOW_SPEED_FRICTION and (z := presliding_m(effect)):  # F_c·h, Dahl's h
            states = [hysteresis_interval_mean(c.deflection_m, z) for c in corners]
            return {FRICTION_UNKNOWNS[0]: signals.suspension_column(states)}
        if self.name is EffectName.LOW_SPEED_FRICTION:

            def peak(v: np.ndarray) -> np.ndarray:
                return friction_force_N(v, 0.0, 1.0, stribeck_velocity_m_s(effect))  # the peak's unit step

            # each step's share of the sample interval, not its value at the sample instant
            static = signals.suspension_column([interval_mean(peak, c.velocity_m_s) for c in corners])
            return dict(zip(FRICTION_UNKNOWNS, (signals.sliding_column, static), strict=True))
        if self.name is EffectName.SPRING_CURVE:
            deflection = [c.spring_deflection_m for c in corners]
            out = {}
            if VehicleConstant.SPRING not in identified:
                out[SPRING_RATE_UNKNOWN] = signals.suspension_column(deflection)
            for name, knot in zip(hinge_unknowns(knots_m), knots_m, strict=True):
                out[name] = signals.suspension_column([hinge(z, knot) for z in deflection])
            return out
        if self.name is EffectName.ANTI_ROLL_BAR:
            roll = corners[0].deflection_m - corners[1].deflection_m
            return {"anti_roll_bar_N_per_m": signals.suspension_column([roll, -roll])}
        if self.name is EffectName.TYRE_STIFFNESS:
            return {TYRE_RATE_UNKNOWN: signals.tyre_column([c.tyre_deflection_m * k for c, k in contact])}
        if self.name is EffectName.GUIDE_FRICTION:  # each mass's own equation (a quarter-car rig's only)
            own = (signals.system.kinematics[x].velocity_m_s for x in ("x_s", "x_t"))  # each mass's velocity
            return dict(zip(GUIDE_FRICTION_NAMES, guide_columns(*own, signals.eq), strict=True))
        return {}

    def offset_change(self, signals: EquationSignals, airborne: list[np.ndarray]) -> np.ndarray | None:
        """tyre_liftoff: while airborne the wheel equation's tyre spring K_t·δ becomes the static load."""
        if self.name is not EffectName.TYRE_LIFTOFF:
            return None
        load, k_t = signals.vehicle.static_wheel_load_N, signals.vehicle.tyre_stiffness_N_per_m
        pairs = zip(signals.corners, airborne, strict=True)
        return signals.tyre_column([a * (load - k_t * c.tyre_deflection_m) for c, a in pairs])


_DESCRIPTIONS = {
    EffectName.SPRING_CURVE: (
        "the suspension spring's force is another curve of deflection than the stated rate: a wrong "
        "rate, a progressive spring, a bump or rebound stop (with or without clearance)",
        "suspension residual following the deflection, or the deflection beyond a clearance",
    ),
    EffectName.LOW_SPEED_FRICTION: (
        "strut and seal friction: a force step at zero velocity, with a static peak above the sliding "
        "level (Stribeck), or hysteretic: building up over a presliding displacement (Dahl)",
        "suspension residual that steps where the suspension velocity changes sign",
    ),
    EffectName.TYRE_STIFFNESS: (
        "the stated tyre rate is wrong (one rate for both tyres of an axle)",
        "wheel-equation residual in phase with the tyre deflection, largest around the wheel hop",
    ),
    EffectName.TYRE_DAMPING: (
        "Kelvin-Voigt dashpot in the tyre, parallel to its spring",
        "wheel-equation residual in phase with the tyre deflection rate, growing with frequency",
    ),
    EffectName.TYRE_VISCOELASTIC: (
        "Maxwell element in the tyre (dashpot in series with a spring, relaxation time from ϑ)",
        "wheel-equation residual following the low-passed tyre deflection rate",
    ),
    EffectName.TYRE_LIFTOFF: (
        "the tyre leaves the plate: the contact force cannot go below zero",
        "wheel-equation residual confined to the moments the tyre would pull on the plate",
    ),
    EffectName.ANTI_ROLL_BAR: (
        "anti-roll bar of an axle: a spring on the difference of left and right deflections",
        "opposite suspension residuals left and right following the deflection difference",
    ),
    EffectName.SENSOR_DYNAMICS: (
        "a sensor channel lags: a delay plus a first-order lag, or plus a moving average (the "
        "amplifier's averaging)",
        "residual following the channel's rate, growing with frequency",
    ),
    EffectName.SENSOR_GAIN: (
        "a channel's scale is off (a wrong head range or calibration)",
        "residual following the channel's reading itself",
    ),
    EffectName.SENSOR_OFFSET: (
        "a channel's zero is off",
        "a constant residual in the wheel equation and a constant output-error offset",
    ),
    EffectName.GUIDE_FRICTION: (
        "a lab rig's body and wheel rub on the frame's guides: a friction against each mass's own motion",
        "body- and wheel-equation residuals that step where that mass's own velocity changes sign",
    ),
}
CATALOG: dict[EffectName, Effect] = {name: Effect(name, *texts) for name, texts in _DESCRIPTIONS.items()}
