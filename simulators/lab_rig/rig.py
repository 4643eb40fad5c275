"""The truth of a lab quarter-car rig, and what its vehicle file states.

A desktop rig of a few kilograms: a body plate (sprung mass) and a wheel carriage (unsprung mass) ride on
linear bearings in a frame; the "tyre" is a coil spring with a rubber pad (the pad's loss a Maxwell
element: dashpot in series with a spring) standing on the road actuator's plate, to which it is fixed, so
it never lifts off; the suspension is a coil spring with the rig's own damper (a small viscous damper plus
the friction of its guide: a Stribeck law, the breakaway force above the sliding one). Between body and
wheel also acts what nobody records:

- an active-suspension voice coil, its force lagging its command by the coil's electrical time constant;
  the command is the lab's controller (skyhook feedback on the body's absolute velocity, from the
  controller's own sensor) plus a reference signal the experiment plays (its own per run), and the coil
  has a cogging ripple along its stroke;
- the coil's cable, which drags with a hysteresis (Dahl's law: pre-sliding stiffness, then a drag level);

and against the frame the linear bearings' friction on the body and on the wheel. The rig's stated spring
and tyre rates are its data-sheet values, 40-80% off the true ones (above or below).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class Friction:
    """A Stribeck friction law: [F_c + (F_s − F_c)·exp(−(v/v_s)²)]·tanh(v/band), opposing the motion.

    sliding_N: F_c; breakaway_N: F_s ≥ F_c, the peak at low speed; stribeck_m_s: v_s, the speed over which
    the force falls from breakaway to sliding; band_m_s: how sharply it reverses through zero speed (a
    regularised sign)."""

    sliding_N: float
    breakaway_N: float
    stribeck_m_s: float
    band_m_s: float = 0.001

    def __post_init__(self) -> None:
        if not (0.0 <= self.sliding_N <= self.breakaway_N):
            raise ValueError("friction needs 0 <= sliding_N <= breakaway_N")
        if not (self.stribeck_m_s > 0.0 and self.band_m_s > 0.0):
            raise ValueError("stribeck_m_s and band_m_s must be > 0")

    def force(self, speed_m_s: float) -> float:
        """The friction force at relative speed v (same sign as v: the caller subtracts it)."""
        level = self.sliding_N + (self.breakaway_N - self.sliding_N) * math.exp(
            -((speed_m_s / self.stribeck_m_s) ** 2)
        )
        return level * math.tanh(speed_m_s / self.band_m_s)


NO_FRICTION = Friction(0.0, 0.0, 1.0)


@dataclass(frozen=True)
class Actuator:
    """The voice coil between body and wheel. Its force F obeys lag_s·Ḟ = u − F with the command
    u = −skyhook_Ns_per_m·ẋ_body + reference(t) (reference: the run's own, see world.RunSpec); the
    cogging ripple cogging_N·sin(2π·(ζ − ζ_rest)/cogging_pitch_m) acts on the suspension deflection ζ (the
    rig comes to rest in a detent)."""

    skyhook_Ns_per_m: float
    lag_s: float
    cogging_N: float
    cogging_pitch_m: float

    def __post_init__(self) -> None:
        if not (self.lag_s > 0.0 and self.cogging_pitch_m > 0.0):
            raise ValueError("the coil's lag_s and cogging_pitch_m must be > 0")


@dataclass(frozen=True)
class CableDrag:
    """Dahl's hysteresis: Ḟ = stiffness·(ζ' − |ζ'|·F/level), F opposing the suspension motion, bounded by
    `level` once sliding."""

    level_N: float
    stiffness_N_per_m: float


@dataclass(frozen=True)
class LabRig:
    """One rig. Rates in N/m, masses in kg. tyre_loss: the pad's Maxwell element (its dashpot
    tyre_loss_Ns_per_m in series with a spring of tyre_loss_Ns_per_m / tyre_loss_relaxation_s).
    stated_spring_factor, stated_tyre_factor: the vehicle file states the true rate × factor."""

    sprung_mass_kg: float
    unsprung_mass_kg: float
    spring_N_per_m: float
    tyre_N_per_m: float
    tyre_loss_Ns_per_m: float
    tyre_loss_relaxation_s: float
    damper_Ns_per_m: float
    damper_friction: Friction
    actuator: Actuator
    cable: CableDrag
    body_bearing: Friction
    wheel_bearing: Friction
    stated_spring_factor: float
    stated_tyre_factor: float
    spring_free_length_m: float = 0.12
    tyre_free_length_m: float = 0.06
    plate_height_m: float = 0.05

    def __post_init__(self) -> None:
        positive = (
            self.sprung_mass_kg,
            self.unsprung_mass_kg,
            self.spring_N_per_m,
            self.tyre_N_per_m,
            self.tyre_loss_relaxation_s,
        )
        if not all(value > 0.0 for value in positive):
            raise ValueError("masses, rates and the pad's relaxation time must be > 0")
        heights = self.static_heights_m()
        if not (heights[0] > heights[1] > self.plate_height_m):
            raise ValueError("the springs are too soft for their free lengths: the rig bottoms out at rest")

    @property
    def total_mass_kg(self) -> float:
        return self.sprung_mass_kg + self.unsprung_mass_kg

    def damper_force_N(self, rate_m_s: float) -> float:
        """The rig's own damper at suspension rate ζ' (body minus wheel velocity): its viscous part and its
        guide's friction, the force a vehicle model's damper curve stands for (same sign as ζ')."""
        return self.damper_Ns_per_m * rate_m_s + self.damper_friction.force(rate_m_s)

    @property
    def tyre_loss_stiffness_N_per_m(self) -> float:
        return self.tyre_loss_Ns_per_m / self.tyre_loss_relaxation_s

    def static_heights_m(self) -> tuple[float, float]:
        """Body and wheel heights above the frame's base at rest, the plate still: the tyre spring carries
        the whole rig, the suspension spring the body."""
        wheel = (
            self.plate_height_m
            + self.tyre_free_length_m
            - self.total_mass_kg * GRAVITY_M_S2 / self.tyre_N_per_m
        )
        body = wheel + self.spring_free_length_m - self.sprung_mass_kg * GRAVITY_M_S2 / self.spring_N_per_m
        return body, wheel

    def stated(self, mass_only: bool = False) -> dict[str, float | str | bool]:
        """The vehicle file's [vehicle] keys: the true total mass, that the masses ride on the frame's
        guides (the lab knows its rig is one), and (unless mass_only) the data sheet's spring and tyre
        rates, as wrong as they are. ϑ is never stated: the pad's loss is not on the data sheet (identify
        finds it)."""
        stated: dict[str, float | str | bool] = {
            "model": "quarter-car",
            "mass_kg": round(self.total_mass_kg, 4),
            "frame_guides": True,
        }
        if not mass_only:
            stated["spring_stiffness_N_per_m"] = round(self.spring_N_per_m * self.stated_spring_factor, 1)
            stated["tyre_stiffness_N_per_m"] = round(self.tyre_N_per_m * self.stated_tyre_factor, 1)
        return stated
