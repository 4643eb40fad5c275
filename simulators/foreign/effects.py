"""The foreign world's effect laws, written from the tribology and elastomer literature's forms and not from
the model doctor's catalogue (which knows F·tanh(v/band), k3·ζ³ and pure delays):

- StribeckFriction: a static friction law whose breakaway peak F_s lies above the sliding level F_c and
  decays to it with the Stribeck velocity v_s, plus a viscous part:
  F(v) = s(v)·(F_c + (F_s − F_c)·exp(−|v/v_s|^δ)) + σ2·v, s(v) = tanh(v/ε) a regularised sign;
- LuGreFriction: hysteretic friction with an internal bristle state z (Canudas de Wit et al. 1995):
  ż = v − σ0·|v|·z/g(v), F = σ0·z + σ1·ż + σ2·v, g(v) = F_c + (F_s − F_c)·exp(−(v/v_s)²). With F_s = F_c
  and σ1 = 0 it is Dahl's model (Ḟ = σ0·(v − |v|·F/F_c)): a force that builds over a presliding
  displacement F_c/σ0 and traces a hysteresis loop in force against displacement;
- BumpStop: an elastomer stop that touches only after a clearance; beyond it the force grows exponentially
  (k·L·(e^(d/L) − 1)) or as a power law (k·L·(d/L)^p) in the penetration d;
- DamperLag: the damper's force lags its velocity law (oil and gas compressibility), either as a first
  order lag τ·Ḟ = f_d(ζ') − F or as the damper in series with a stiffness k (F = k·y, ẏ = ζ' − f_d⁻¹(F));
- UnrecordedForce: a force between body and wheel that no channel records (a cable, an actuator, a hand),
  a sum of sines at incommensurate frequencies that fades in over the first 0.3 s.

Signs: extension ζ = x_body − x_wheel is positive when the suspension lengthens; every `force` here is the
force the effect exerts up on the body (down on the wheel); friction returns −(its resistance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

FADE_IN_S = 0.3


def _sign(velocity_m_s: float, smoothing_m_s: float) -> float:
    return math.tanh(velocity_m_s / smoothing_m_s)


@dataclass(frozen=True)
class StribeckFriction:
    """A static (memoryless) Stribeck law; smoothing_m_s regularises the sign at zero velocity."""

    sliding_N: float
    static_N: float
    stribeck_velocity_m_s: float
    shape_exponent: float = 2.0
    viscous_Ns_per_m: float = 0.0
    smoothing_m_s: float = 0.001

    def __post_init__(self) -> None:
        if not 0.0 < self.sliding_N <= self.static_N:
            raise ValueError("Stribeck friction needs 0 < sliding_N <= static_N")

    def resistance(self, velocity_m_s: float) -> float:
        """The friction force resisting the motion at this suspension velocity (positive for v > 0)."""
        decay = math.exp(-(abs(velocity_m_s / self.stribeck_velocity_m_s) ** self.shape_exponent))
        level = self.sliding_N + (self.static_N - self.sliding_N) * decay
        return _sign(velocity_m_s, self.smoothing_m_s) * level + self.viscous_Ns_per_m * velocity_m_s

    def force(self, velocity_m_s: float) -> float:
        return -self.resistance(velocity_m_s)


@dataclass(frozen=True)
class LuGreFriction:
    """LuGre friction (Dahl's when static_N == sliding_N and bristle_damping_Ns_per_m == 0); state z (m)."""

    sliding_N: float
    static_N: float
    stribeck_velocity_m_s: float
    bristle_stiffness_N_per_m: float
    bristle_damping_Ns_per_m: float = 0.0
    viscous_Ns_per_m: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 < self.sliding_N <= self.static_N or self.bristle_stiffness_N_per_m <= 0.0:
            raise ValueError("LuGre friction needs 0 < sliding_N <= static_N and a bristle stiffness")

    @property
    def kind(self) -> str:
        dahl = self.static_N == self.sliding_N and self.bristle_damping_Ns_per_m == 0.0
        return "dahl" if dahl else "lugre"

    @property
    def presliding_m(self) -> float:
        """The displacement over which the force builds up to the sliding level."""
        return self.sliding_N / self.bristle_stiffness_N_per_m

    def level(self, velocity_m_s: float) -> float:
        decay = math.exp(-((velocity_m_s / self.stribeck_velocity_m_s) ** 2))
        return self.sliding_N + (self.static_N - self.sliding_N) * decay

    def state_rate(self, bristle_m: float, velocity_m_s: float) -> float:
        sigma0 = self.bristle_stiffness_N_per_m
        return velocity_m_s - sigma0 * abs(velocity_m_s) * bristle_m / self.level(velocity_m_s)

    def resistance(self, bristle_m: float, velocity_m_s: float) -> float:
        return (
            self.bristle_stiffness_N_per_m * bristle_m
            + self.bristle_damping_Ns_per_m * self.state_rate(bristle_m, velocity_m_s)
            + self.viscous_Ns_per_m * velocity_m_s
        )

    def force(self, bristle_m: float, velocity_m_s: float) -> float:
        return -self.resistance(bristle_m, velocity_m_s)


@dataclass(frozen=True)
class BumpStop:
    """side: "compression" (touches when the suspension shortens by more than clearance_m) or "rebound"
    (lengthens by more). stiffness_N_per_m: the elastomer's stiffness scale k, length_m its length scale L,
    exponent p of the power law."""

    side: Literal["compression", "rebound"]
    clearance_m: float
    stiffness_N_per_m: float
    length_m: float
    law: Literal["exponential", "power"] = "exponential"
    exponent: float = 2.0

    def penetration_m(self, extension_m: float) -> float:
        travel = -extension_m if self.side == "compression" else extension_m
        return max(0.0, travel - self.clearance_m)

    def magnitude_N(self, penetration_m: float) -> float:
        if penetration_m <= 0.0:
            return 0.0
        scale = self.stiffness_N_per_m * self.length_m
        ratio = penetration_m / self.length_m
        return scale * math.expm1(ratio) if self.law == "exponential" else scale * ratio**self.exponent

    def force(self, extension_m: float) -> float:
        """Up on the body: a compression stop pushes the body up, a rebound stop pulls it down."""
        magnitude = self.magnitude_N(self.penetration_m(extension_m))
        return magnitude if self.side == "compression" else -magnitude


@dataclass(frozen=True)
class DamperLag:
    """kind "first_order": the force follows the velocity law with time constant time_constant_s; kind
    "series_stiffness": the damper sits in series with series_stiffness_N_per_m (its state is the spring's
    deflection)."""

    kind: Literal["first_order", "series_stiffness"]
    time_constant_s: float = 0.0
    series_stiffness_N_per_m: float = 0.0

    def __post_init__(self) -> None:
        if self.kind == "first_order" and self.time_constant_s <= 0.0:
            raise ValueError("a first-order damper lag needs a positive time constant")
        if self.kind == "series_stiffness" and self.series_stiffness_N_per_m <= 0.0:
            raise ValueError("a damper in series needs a positive stiffness")


@dataclass(frozen=True)
class UnrecordedForce:
    """Σ a_i·sin(2π f_i t + φ_i), faded in by a raised cosine over FADE_IN_S; up on the body."""

    amplitudes_N: tuple[float, ...]
    frequencies_Hz: tuple[float, ...]
    phases_rad: tuple[float, ...]

    @property
    def rms_N(self) -> float:
        return math.sqrt(0.5 * sum(a * a for a in self.amplitudes_N))

    def force(self, t_s: float) -> float:
        if t_s <= 0.0:
            return 0.0
        window = 1.0 if t_s >= FADE_IN_S else 0.5 * (1.0 - math.cos(math.pi * t_s / FADE_IN_S))
        total = 0.0
        for a, f, p in zip(self.amplitudes_N, self.frequencies_Hz, self.phases_rad, strict=True):
            total += a * math.sin(2.0 * math.pi * f * t_s + p)
        return window * total


@dataclass(frozen=True)
class ForceEffects:
    """The force effects of one vehicle (the same on both corners of an axle)."""

    stribeck: StribeckFriction | None = None
    lugre: LuGreFriction | None = None
    bump_stops: tuple[BumpStop, ...] = ()
    damper_lag: DamperLag | None = None
    unrecorded: UnrecordedForce | None = None
