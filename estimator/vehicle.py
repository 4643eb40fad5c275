"""What is known about the vehicle before the test: the constants of the paper's Table 1 with names that say
what they are, and which of them are left to the identification.

The paper's Table 1 swaps the descriptions of K_s and K_a; here the suspension spring is `spring_stiffness`
(14 040 N/m in the paper) and the tyre is `tyre_stiffness` (101 018 N/m).

Only the mass is required. A stiffness or the tyre's viscoelastic coefficient that is not known (None) is
identified from the recording (estimator.identify): the stiffnesses are further linear unknowns of the same
residual system, ϑ is found by a bounded search over convex solves.

ϑ and the sample time. The paper's ϑ = γ/(1+γ) with γ = C_d/(K_d·Δt) depends on the sample time Δt: it
stands for the Maxwell element's relaxation time τ = C_d/K_d = Δt·ϑ/(1−ϑ), which does not. Here ϑ is always
referred to REFERENCE_SAMPLE_TIME_S = 1 ms (the paper's Δt and the bench's rate), whatever the recording's
rate: the paper's 0.97 means τ = 32.3 ms, and a recording at 2 ms uses ϑ_2ms = τ/(τ + 2 ms) = 0.942
(`viscoelastic_coefficient_at`). A vehicle file may give `tyre_relaxation_time_s` instead.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum

from estimator.errors import InvalidValueError


class ModelKind(StrEnum):
    QUARTER_CAR = "quarter-car"
    AXLE = "axle"


class TyreModel(StrEnum):
    """How the tyre's vertical force is modelled besides its spring (paper section 2)."""

    MAXWELL = "maxwell"  # spring in parallel with a Maxwell element (damper C_d in series with spring K_d)
    KELVIN_VOIGT = "kelvin-voigt"  # spring in parallel with a dashpot C_d
    SPRING = "spring"  # constant stiffness only


class VehicleConstant(StrEnum):
    """A constant of the vehicle file that the identification can find instead (`identify --free`)."""

    SPRING = "spring"  # spring_stiffness_N_per_m, K_s (one value for both springs of an axle)
    TYRE = "tyre"  # tyre_stiffness_N_per_m, K_t (one value for both tyres of an axle)
    THETA = "theta"  # tyre_viscoelastic_coefficient ϑ, i.e. the Maxwell relaxation time (maxwell tyre only)
    BAR = "bar"  # anti_roll_bar_stiffness_N_per_m, K_e (axle only)


STANDARD_GRAVITY_M_S2 = 9.80665
REFERENCE_SAMPLE_TIME_S = 0.001
"""The sample time the vehicle file's ϑ is referred to (the paper's Table 1: Δt = 1 ms)."""


def coefficient_from_relaxation_time(relaxation_time_s: float, sample_time_s: float) -> float:
    """ϑ = γ/(1+γ) with γ = τ/Δt, i.e. τ/(τ + Δt)."""
    return relaxation_time_s / (relaxation_time_s + sample_time_s)


def relaxation_time_from_coefficient(coefficient: float, sample_time_s: float) -> float:
    """τ = γ·Δt with γ = ϑ/(1−ϑ)."""
    return sample_time_s * coefficient / (1.0 - coefficient)


@dataclass(frozen=True)
class VehicleParameters:
    """Known constants of the wheel(s) under test; None = not known, identified from the recording.

    mass_kg: the mass carried by the wheel(s) under test, M_1/4 for a quarter car, M_1/2 for an axle
        (sprung plus unsprung); the estimator splits it. The only constant that cannot be identified: it
        fixes the scale of every force.
    spring_stiffness_N_per_m, tyre_stiffness_N_per_m: K_s and K_t (an axle: the same for both sides).
    tyre_viscoelastic_coefficient: the paper's ϑ = γ/(1+γ), γ = C_d/(K_d·Δt), referred to Δt = 1 ms
        (REFERENCE_SAMPLE_TIME_S) whatever the recording's sample time; see the module docstring.
    track_m: wheel track b (axle only). anti_roll_bar_stiffness_N_per_m: K_e (axle only; 0 = no bar).
    frame_guides: the body and the wheel ride on guides fixed to a frame (a laboratory quarter-car rig, not a
        vehicle on a plate), so each feels a friction against the frame (quarter car only).
    """

    model: ModelKind
    mass_kg: float
    spring_stiffness_N_per_m: float | None = None
    tyre_stiffness_N_per_m: float | None = None
    tyre_viscoelastic_coefficient: float | None = None
    track_m: float | None = None
    anti_roll_bar_stiffness_N_per_m: float = 0.0
    frame_guides: bool = False

    def __post_init__(self) -> None:
        if not self.mass_kg > 0:
            raise InvalidValueError(f"mass_kg must be > 0, got {self.mass_kg}")
        for name in ("spring_stiffness_N_per_m", "tyre_stiffness_N_per_m"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise InvalidValueError(f"{name} must be > 0, got {value}")
        theta = self.tyre_viscoelastic_coefficient
        if theta is not None and not 0.0 <= theta < 1.0:
            raise InvalidValueError("tyre_viscoelastic_coefficient (ϑ) must be in [0, 1)")
        if self.model is ModelKind.AXLE and (self.track_m is None or not self.track_m > 0):
            raise InvalidValueError("an axle needs track_m > 0")
        if self.anti_roll_bar_stiffness_N_per_m < 0:
            raise InvalidValueError("anti_roll_bar_stiffness_N_per_m must be >= 0")
        if self.frame_guides and self.model is ModelKind.AXLE:
            raise InvalidValueError("frame_guides applies to a quarter-car rig only")

    @property
    def is_axle(self) -> bool:
        return self.model is ModelKind.AXLE

    @property
    def unknown(self) -> frozenset[VehicleConstant]:
        """The constants the vehicle file does not state (never the anti-roll bar: absent means none)."""
        missing = {
            VehicleConstant.SPRING: self.spring_stiffness_N_per_m,
            VehicleConstant.TYRE: self.tyre_stiffness_N_per_m,
            VehicleConstant.THETA: self.tyre_viscoelastic_coefficient,
        }
        return frozenset(name for name, value in missing.items() if value is None)

    @property
    def tyre_relaxation_time_s(self) -> float | None:
        """τ = C_d/K_d of the Maxwell element, from ϑ referred to 1 ms (None when ϑ is not known)."""
        theta = self.tyre_viscoelastic_coefficient
        return None if theta is None else relaxation_time_from_coefficient(theta, REFERENCE_SAMPLE_TIME_S)

    def viscoelastic_coefficient_at(self, sample_time_s: float) -> float:
        """ϑ for a recording sampled every sample_time_s: τ/(τ + Δt) (eq 4 at that Δt)."""
        tau = self.maxwell_time_constant_s()
        return coefficient_from_relaxation_time(tau, sample_time_s)

    def maxwell_time_constant_s(self, sample_time_s: float | None = None) -> float:
        """τ = C_d/K_d (paper eq 5). It does not depend on the recording's sample time, since ϑ is referred
        to 1 ms; `sample_time_s` is accepted (and not needed) for callers that pass the recording's."""
        tau = self.tyre_relaxation_time_s
        if tau is None:
            raise InvalidValueError("the tyre's viscoelastic coefficient ϑ is not known: identify it first")
        return tau

    def with_relaxation_time(self, relaxation_time_s: float) -> VehicleParameters:
        """A copy with ϑ set from a relaxation time τ (ϑ = τ/(τ + 1 ms))."""
        theta = coefficient_from_relaxation_time(relaxation_time_s, REFERENCE_SAMPLE_TIME_S)
        return replace(self, tyre_viscoelastic_coefficient=theta)

    @property
    def static_wheel_load_N(self) -> float:
        """Static vertical load on one tyre."""
        return self.mass_kg * STANDARD_GRAVITY_M_S2 / self.wheels

    @property
    def wheels(self) -> int:
        return 2 if self.is_axle else 1

    def unsprung_mass_kg(self, sprung_mass_kg: float) -> float:
        """Unsprung mass per wheel, (M - M_s) / wheels: the one place this conversion is written (numpy
        arrays of sprung masses work too)."""
        return (self.mass_kg - sprung_mass_kg) / self.wheels


PAPER_BENCH = VehicleParameters(
    model=ModelKind.QUARTER_CAR,
    mass_kg=109.3,
    spring_stiffness_N_per_m=14_040.0,
    tyre_stiffness_N_per_m=101_018.0,
    tyre_viscoelastic_coefficient=0.97,
)
"""The paper's motorcycle-fork bench (Table 1, with K_s and K_a put the right way round)."""
