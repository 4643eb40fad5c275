"""The catalog of candidate effects: each a named extension of the model that the estimator can fit, with the
signature it leaves in the residuals of a model that lacks it.

Two kinds of extension:

- *force* effects add unknowns that enter the equations of motion linearly (a column each, see
  estimator.doctor.columns), so the paper's objective stays convex and the exact solver fits them with the
  damper curve: tyre_damping, tyre_viscoelastic, coulomb_friction, progressive_spring, anti_roll_bar, and
  the corrections of a stated stiffness that the data contradict, spring_stiffness (ΔK_s on the suspension
  deflection) and tyre_stiffness (ΔK_t on the tyre deflection, zero where the tyre is off the plate). An
  axle gets one correction for both springs and one for both tyres: the vehicle file states one value for
  both sides, and a per-side spring correction would share its roll part with anti_roll_bar.
  tyre_liftoff has no unknown: where the tyre would pull on the plate the tyre force is replaced by the
  static wheel load (the contact force cannot go below zero), and the tyre's Maxwell element is not driven
  there (it relaxes in the air and lands with what is left of its force, as in the simulation,
  estimator.dynamics). Driven by the wheel's rate through the flight, it landed with a force the tyre does
  not have: on an independent lift-off recording (van, 2.4% airborne) the named model's gap was 389 µm
  against 62 µm with the element relaxing.
- *channel* effects correct one sensor channel before the equations are built: channel_delay (the channel
  lags the others by delay_s) and sensor_offset (its zero is off by offset_m). They are fitted by
  Gauss-Newton steps on the objective (estimator.doctor.model).

The names are stable: they are what `shockbench diagnose --json` prints.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from estimator.doctor.columns import EquationSignals, interval_mean
from estimator.dynamics import coulomb_sign
from estimator.recording import Recording
from estimator.vehicle import VehicleConstant, VehicleParameters


class EffectName(StrEnum):
    TYRE_DAMPING = "tyre_damping"
    TYRE_VISCOELASTIC = "tyre_viscoelastic"
    COULOMB_FRICTION = "coulomb_friction"
    TYRE_LIFTOFF = "tyre_liftoff"
    PROGRESSIVE_SPRING = "progressive_spring"
    ANTI_ROLL_BAR = "anti_roll_bar"
    CHANNEL_DELAY = "channel_delay"
    SENSOR_OFFSET = "sensor_offset"
    SPRING_STIFFNESS = "spring_stiffness"
    TYRE_STIFFNESS = "tyre_stiffness"


@dataclass(frozen=True, order=True)
class EffectInstance:
    """An effect as added to a model; channel effects name their channel."""

    name: EffectName
    channel: str | None = None

    @property
    def label(self) -> str:
        return f"{self.name.value}({self.channel})" if self.channel else self.name.value


MAX_DELAY_S = 0.02
"""A channel delay is searched in [0, this]."""
MIN_DELAY_S = 1e-4
"""A fitted delay below this (a tenth of a sample at 1 kHz) does not count as a delay."""
MIN_DELAY_SAMPLES = 0.25
"""Nor does a delay below this share of the sample time. A lag that small is what the sub-sample shift of a
channel (cubic interpolation) turns into a stand-in for a damper curve that misses the damper near zero
velocity: on clean recordings of the independent world with the FSAE s5 table (a dead band of a few
newtons up to 4 mm/s, then 350 N at 23 mm/s, which the doctor's knots 13 mm/s apart cannot follow) a delay
of the wheel channel of 0.12-0.2 ms at 1 ms sampling lowered the gap by a third and was named; the delays
of a data acquisition that lags are whole samples or more (the world hides 1-5 ms)."""
MIN_AIRBORNE_FRACTION = 0.002
"""tyre_liftoff needs the tyre off the plate during at least this fraction of the recording."""
FRICTION_BAND_M_S = 0.02
"""With coulomb_friction the damper curve is one straight line over ±this suspension velocity (its grid gets
knots at ±this and none between), whose slope is tied to the curve's slopes either side
(estimator.doctor.model.friction_grids, friction_constraints): only the friction term can step at zero
velocity. Without this the curve's interval across zero (0.01-0.04 m/s wide with the doctor's 30 points)
turns steep and takes part of the step, and how much it takes changes over the sweep: on an independent
recording with 131 N of friction the friction fitted on the two halves of the sweep was 316 N and 8 N. The
band is narrower than a damper's low-speed knee (the SUV table's at 0.04 m/s, the valve models' bleed) and
wider than the step of strut friction (a few mm/s) and the velocity estimate's noise."""
MIN_FRICTION_SHARE = 0.025
"""coulomb_friction needs a friction of at least this share of the peak damper force (half of the 5% the
doctor must find), and SIGNIFICANCE_Z standard errors: with the band's knots the curve of a clean recording
fits better too (a knee near zero is followed more closely), and a few newtons of friction are then not
evidence of friction."""
MIN_STIFFNESS_CHANGE = 0.08
"""spring_stiffness and tyre_stiffness need the identified rate to differ from the stated one by at least
this fraction. The noise-driven 95% band of a stiffness is a fraction of a per cent (estimator.uncertainty),
but on recordings of a world that is not the estimator's own discretisation a complete model with the right
rates can identify them off: within 1% on six clean recordings of the independent world, but up to 7% when
another effect is missing and the rate stands in for part of it (the tyre rate of a recording with a wrong
spring rate, the spring rate of one with friction). A vehicle file 8% off is within what a maker's tolerance
and a tyre's pressure account for anyway."""
SIGNIFICANCE_Z = 3.0
"""spring_stiffness and tyre_stiffness need the change, coulomb_friction the force, to be at least this many
standard errors (sandwich covariance with a block long-run variance, estimator.uncertainty): what the data
cannot tell from zero is not named."""
CONFIRMED_SIGNIFICANCE_Z = 2.0
"""SIGNIFICANCE_Z for a candidate whose gap falls by the doctor's min_gap_reduction on its own
(estimator.doctor.judging.Judging.score): the output confirms what the equations say, and the sandwich
standard error with a block long-run variance counts the misfit of everything the model still lacks as
noise. Independent world, friction of 83-87 N on vans at 2 ms (2.5 and 2.2 standard errors): the gap fell
41-45%, objective 0.82-0.85, correlation 0.68-0.71."""
ENTANGLED = {
    EffectName.SPRING_STIFFNESS: EffectName.PROGRESSIVE_SPRING,
    EffectName.PROGRESSIVE_SPRING: EffectName.SPRING_STIFFNESS,
}
"""Effects whose unknowns share one signal, so that while one is missing the other cannot be fitted right on
its own: the spring's rate change ΔK_s on the suspension deflection x and a bump stop's k3 on x³ (x and x³
are strongly correlated over a sweep). When nothing qualifies alone, the doctor tries the two together
(estimator.doctor.diagnose._Doctor.look_ahead). Independent world, car, spring stated ×1.21 with a bump stop
of +31% at 6 mm: alone, the rate change came out -7.6% (below MIN_STIFFNESS_CHANGE, gap -1%) and k3 softened
the spring (-3%); together -19.1% (truth -17.6%) and k3 8.28e7 N/m³ (truth 8.30e7), objective 0.72, gap
204 → 142 µm."""
STIFFNESS_UNKNOWNS = {
    VehicleConstant.SPRING: "spring_stiffness_change_N_per_m",
    VehicleConstant.TYRE: "tyre_stiffness_change_N_per_m",
}
"""The unknown each stiffness correction adds to θ: ΔK, the identified rate minus the stated one (N/m)."""


@dataclass(frozen=True)
class Effect:
    """One catalog entry. `summary`: what it is physically; `signature`: what a model that lacks it leaves
    in the residuals; `signal`: in words, the signal the residual follows when the effect is missing
    ({channel} stands for the channel of a channel effect)."""

    name: EffectName
    summary: str
    signature: str
    signal: str
    channel_kind: str | None = None
    """"delay" or "offset" for channel effects, None for force effects."""

    @property
    def stiffness(self) -> VehicleConstant | None:
        """The vehicle constant a stiffness correction corrects (None for other effects)."""
        return {
            EffectName.SPRING_STIFFNESS: VehicleConstant.SPRING,
            EffectName.TYRE_STIFFNESS: VehicleConstant.TYRE,
        }.get(self.name)

    def instances(
        self,
        vehicle: VehicleParameters,
        recording: Recording,
        identified: frozenset[VehicleConstant] = frozenset(),
    ) -> list[EffectInstance]:
        """The ways this effect can be added to a model of this vehicle and recording. identified: the
        constants the vehicle file did not state (identified from this recording before the diagnosis): a
        stiffness that was not stated cannot contradict the data."""
        if self.stiffness is not None:
            return [] if self.stiffness in identified else [EffectInstance(self.name)]
        if self.name is EffectName.ANTI_ROLL_BAR:
            known_bar = vehicle.anti_roll_bar_stiffness_N_per_m > 0
            return [EffectInstance(self.name)] if vehicle.is_axle and not known_bar else []
        if self.channel_kind is None:
            return [EffectInstance(self.name)]
        names = sorted(recording.channels)
        if self.channel_kind == "offset":
            # a zero error of a body channel only shifts the damper curve by a constant force (the curve's
            # basis sums to one): it changes neither the residuals nor the gap, so it cannot be diagnosed
            names = [n for n in names if not n.startswith("x_s")]
        return [EffectInstance(self.name, n) for n in names]

    def columns(self, signals: EquationSignals, airborne: list[np.ndarray]) -> dict[str, np.ndarray]:
        """Unknown name -> (equations, samples) column, for force effects; airborne: per corner, where the
        tyre has left the plate (tyre forces are zero there)."""
        corners = signals.corners
        contact = [1.0 - a for a in airborne]
        if self.name is EffectName.TYRE_DAMPING:
            series = [c.tyre_rate_m_s * k for c, k in zip(corners, contact, strict=True)]
            return {"tyre_dashpot_Ns_per_m": signals.tyre_column(series)}
        if self.name is EffectName.TYRE_VISCOELASTIC:
            # off the plate nothing drives the element: it relaxes, and lands with what is left of its force
            series = [
                signals.maxwell_regressor(c.tyre_rate_m_s * k) * k
                for c, k in zip(corners, contact, strict=True)
            ]
            return {"maxwell_damping_Ns_per_m": signals.tyre_column(series)}
        if self.name is EffectName.COULOMB_FRICTION:
            # the step's share of each sample interval, not its value at the sample instant
            series = [interval_mean(coulomb_sign, c.velocity_m_s) for c in corners]
            return {"coulomb_friction_N": signals.suspension_column(series)}
        if self.name is EffectName.PROGRESSIVE_SPRING:
            return {"cubic_spring_N_per_m3": signals.suspension_column([c.deflection_m**3 for c in corners])}
        if self.name is EffectName.ANTI_ROLL_BAR:
            roll = corners[0].deflection_m - corners[1].deflection_m
            return {"anti_roll_bar_N_per_m": signals.suspension_column([roll, -roll])}
        if self.name is EffectName.SPRING_STIFFNESS:
            # the deflection as the equations' own spring term has it (raw channels, equation low-pass)
            series = [c.spring_deflection_m for c in corners]
            return {STIFFNESS_UNKNOWNS[VehicleConstant.SPRING]: signals.suspension_column(series)}
        if self.name is EffectName.TYRE_STIFFNESS:
            series = [c.tyre_deflection_m * k for c, k in zip(corners, contact, strict=True)]
            return {STIFFNESS_UNKNOWNS[VehicleConstant.TYRE]: signals.tyre_column(series)}
        return {}

    def offset_change(self, signals: EquationSignals, airborne: list[np.ndarray]) -> np.ndarray | None:
        """tyre_liftoff: while airborne the wheel equation's tyre spring K_t·δ becomes the static load."""
        if self.name is not EffectName.TYRE_LIFTOFF:
            return None
        load = signals.vehicle.static_wheel_load_N
        stiffness = signals.vehicle.tyre_stiffness_N_per_m
        series = [
            a * (load - stiffness * c.tyre_deflection_m)
            for c, a in zip(signals.corners, airborne, strict=True)
        ]
        return signals.tyre_column(series)

    def report(
        self, instance: EffectInstance, values: dict[str, float], context: FitContext
    ) -> dict[str, float | str]:
        """The fitted parameters as shown to the user (SI units in the names)."""
        if self.name is EffectName.TYRE_DAMPING:
            return {"tyre_dashpot_Ns_per_m": values["tyre_dashpot_Ns_per_m"]}
        if self.name is EffectName.TYRE_VISCOELASTIC:
            return {
                "tyre_damping_Ns_per_m": values["maxwell_damping_Ns_per_m"],
                "relaxation_time_s": context.maxwell_time_constant_s,
            }
        if self.name is EffectName.COULOMB_FRICTION:
            return {"coulomb_friction_N": values["coulomb_friction_N"]}
        if self.name is EffectName.PROGRESSIVE_SPRING:
            k3 = values["cubic_spring_N_per_m3"]
            peak = context.peak_deflection_m
            return {
                "cubic_spring_N_per_m3": k3,
                "stiffening_at_peak_deflection_percent": 100.0
                * 3.0
                * k3
                * peak**2
                / context.spring_stiffness,
                "peak_deflection_m": peak,
            }
        if self.name is EffectName.ANTI_ROLL_BAR:
            return {"anti_roll_bar_stiffness_N_per_m": values["anti_roll_bar_N_per_m"]}
        if self.stiffness is not None:
            key = self.stiffness.value
            change = values[STIFFNESS_UNKNOWNS[self.stiffness]]
            stated = context.stated_stiffness_N_per_m[self.stiffness]
            return {
                f"{key}_stiffness_N_per_m": stated + change,
                f"stated_{key}_stiffness_N_per_m": stated,
                "change_percent": 100.0 * change / stated,
            }
        if self.name is EffectName.TYRE_LIFTOFF:
            return {
                "static_wheel_load_N": context.static_wheel_load_N,
                "airborne_fraction": context.airborne_fraction,
            }
        if self.name is EffectName.CHANNEL_DELAY:
            return {"channel": str(instance.channel), "delay_s": values["delay_s"]}
        return {"channel": str(instance.channel), "offset_m": values["offset_m"]}

    def implausible(self, values: dict[str, float], context: FitContext) -> str | None:
        """Why the fitted values cannot be this effect (None if they can): a dissipative element must
        dissipate, a bump stop must stiffen, a lag must lag, a lift-off must happen."""
        if self.name is EffectName.TYRE_DAMPING:
            value = values["tyre_dashpot_Ns_per_m"]
            return (
                None if 0.0 < value < 20_000.0 else f"fitted tyre dashpot {value:.0f} N·s/m is not a damper"
            )
        if self.name is EffectName.TYRE_VISCOELASTIC:
            value = values["maxwell_damping_Ns_per_m"]
            return (
                None
                if 0.0 < value < 50_000.0
                else f"fitted Maxwell damping {value:.0f} N·s/m is not a damper"
            )
        if self.name is EffectName.COULOMB_FRICTION:
            value = values["coulomb_friction_N"]
            limit = context.static_wheel_load_N
            if not 0.0 < value < limit:
                return f"fitted friction {value:.0f} N does not oppose the motion"
            floor = MIN_FRICTION_SHARE * context.peak_damper_force_N
            if value < floor:
                return (
                    f"fitted friction {value:.0f} N is less than {100 * MIN_FRICTION_SHARE:g}% of the peak "
                    f"damper force ({floor:.0f} N)"
                )
            error = context.standard_error.get("coulomb_friction_N", 0.0)
            if value < context.significance_z * error:
                return (
                    f"fitted friction {value:.0f} N is within {context.significance_z:g} standard errors "
                    f"({error:.0f} N)"
                )
            return None
        if self.name is EffectName.PROGRESSIVE_SPRING:
            value = values["cubic_spring_N_per_m3"]
            return (
                None if value > 0.0 else "the fitted cubic term softens the spring instead of stiffening it"
            )
        if self.name is EffectName.ANTI_ROLL_BAR:
            value = values["anti_roll_bar_N_per_m"]
            return None if value > 0.0 else f"fitted bar stiffness {value:.0f} N/m is negative"
        if self.stiffness is not None:
            return _implausible_stiffness(self.stiffness, values, context)
        if self.name is EffectName.TYRE_LIFTOFF:
            if context.airborne_fraction < MIN_AIRBORNE_FRACTION:
                return "the tyre never leaves the plate in the fitted model"
            return None
        if self.name is EffectName.CHANNEL_DELAY:
            value = values["delay_s"]
            if value < max(MIN_DELAY_S, MIN_DELAY_SAMPLES * context.sample_time_s):
                return f"fitted delay {value * 1e3:.2f} ms is not a lag"
            return None if value < MAX_DELAY_S * 0.99 else "fitted delay runs into the search limit"
        return None


def _implausible_stiffness(
    constant: VehicleConstant, values: dict[str, float], context: FitContext
) -> str | None:
    """A corrected rate must be positive and differ from the stated one by more than the fit's confidence
    allows (MIN_STIFFNESS_CHANGE, SIGNIFICANCE_Z standard errors)."""
    change = values[STIFFNESS_UNKNOWNS[constant]]
    stated = context.stated_stiffness_N_per_m[constant]
    name = f"{constant.value} rate"
    if stated + change <= 0.0:
        return f"the identified {name} {stated + change:.0f} N/m is not positive"
    if abs(change) < MIN_STIFFNESS_CHANGE * stated:
        return (
            f"the identified {name} differs from the stated {stated:.0f} N/m by only "
            f"{100 * change / stated:+.1f}% (less than {100 * MIN_STIFFNESS_CHANGE:.0f}%)"
        )
    error = context.standard_error.get(STIFFNESS_UNKNOWNS[constant], 0.0)
    if abs(change) < context.significance_z * error:
        z = context.significance_z
        return f"the change {change:+.0f} N/m is within {z:g} standard errors ({error:.0f} N/m)"
    return None


@dataclass(frozen=True)
class FitContext:
    """What reports and plausibility checks need to know about the fitted model besides its values.
    stated_stiffness_N_per_m: the vehicle file's rates; standard_error: of the stiffness corrections and the
    friction in θ, by unknown name (only where the model has them); peak_damper_force_N: the largest force
    of the fitted curve(s) over their grid."""

    spring_stiffness: float
    static_wheel_load_N: float
    maxwell_time_constant_s: float
    peak_deflection_m: float
    airborne_fraction: float
    stated_stiffness_N_per_m: dict[VehicleConstant, float]
    standard_error: dict[str, float]
    peak_damper_force_N: float
    sample_time_s: float = 0.0
    """The recording's sample time (s)."""
    significance_z: float = SIGNIFICANCE_Z
    """How many standard errors a friction or a stiffness change must be (the judging lowers it to
    CONFIRMED_SIGNIFICANCE_Z when the gap confirms the candidate on its own)."""


CATALOG: dict[EffectName, Effect] = {
    effect.name: effect
    for effect in (
        Effect(
            EffectName.TYRE_DAMPING,
            "Kelvin-Voigt dashpot in the tyre, parallel to its spring",
            "wheel-equation residual in phase with the tyre deflection rate, growing with frequency",
            "the tyre deflection rate",
        ),
        Effect(
            EffectName.TYRE_VISCOELASTIC,
            "Maxwell element in the tyre (dashpot in series with a spring, relaxation time from ϑ)",
            "wheel-equation residual following the low-passed tyre deflection rate: damper-like below the "
            "relaxation frequency, spring-like above",
            "the low-passed (Maxwell-filtered) tyre deflection rate",
        ),
        Effect(
            EffectName.COULOMB_FRICTION,
            "strut and seal friction: a force of constant size opposing the suspension velocity",
            "suspension residual that steps where the suspension velocity changes sign",
            "the sign of the suspension velocity",
        ),
        Effect(
            EffectName.TYRE_LIFTOFF,
            "the tyre leaves the plate: the contact force cannot go below zero",
            "wheel-equation residual confined to the moments the tyre would pull on the plate",
            "the tyre deflection beyond the static deflection",
        ),
        Effect(
            EffectName.PROGRESSIVE_SPRING,
            "bump stop or progressive spring: a cubic stiffening k3·ζ³",
            "suspension residual growing with the cube of the suspension deflection",
            "the cube of the suspension deflection",
        ),
        Effect(
            EffectName.ANTI_ROLL_BAR,
            "anti-roll bar of an axle: a spring on the difference of left and right deflections",
            "opposite suspension residuals left and right following the deflection difference",
            "the difference of the left and right suspension deflections",
        ),
        Effect(
            EffectName.CHANNEL_DELAY,
            "one sensor channel lags the others",
            "residual following the channel's rate, growing with frequency",
            "the rate of {channel}",
            channel_kind="delay",
        ),
        Effect(
            EffectName.SENSOR_OFFSET,
            "a channel's zero is off",
            "a constant residual in the wheel equation and a constant output-error offset",
            "a constant (the zero error of {channel})",
            channel_kind="offset",
        ),
        Effect(
            EffectName.SPRING_STIFFNESS,
            "the stated spring rate is wrong: the suspension spring is stiffer or softer than the vehicle "
            "file says (one rate for both springs of an axle)",
            "suspension residual in phase with the suspension deflection, the same at every deflection "
            "(a bump stop's grows with its cube), largest around the body resonance",
            "the suspension deflection",
        ),
        Effect(
            EffectName.TYRE_STIFFNESS,
            "the stated tyre rate is wrong: the tyre is stiffer or softer than the vehicle file says (one "
            "rate for both tyres of an axle)",
            "wheel-equation residual in phase with the tyre deflection, largest around the wheel hop",
            "the tyre deflection",
        ),
    )
}
