"""What is known about the vehicle before the test: the constants of the paper's Table 1 with names that say
what they are.

The paper's Table 1 swaps the descriptions of K_s and K_a; here the suspension spring is `spring_stiffness`
(14 040 N/m in the paper) and the tyre is `tyre_stiffness` (101 018 N/m).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class ModelKind(StrEnum):
    QUARTER_CAR = "quarter-car"
    AXLE = "axle"


class TyreModel(StrEnum):
    """How the tyre's vertical force is modelled besides its spring (paper section 2)."""

    MAXWELL = "maxwell"  # spring in parallel with a Maxwell element (damper C_d in series with spring K_d)
    KELVIN_VOIGT = "kelvin-voigt"  # spring in parallel with a dashpot C_d
    SPRING = "spring"  # constant stiffness only


STANDARD_GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class VehicleParameters:
    """Known constants of the wheel(s) under test.

    mass_kg: the mass carried by the wheel(s) under test, M_1/4 for a quarter car, M_1/2 for an axle
        (sprung plus unsprung); the estimator splits it.
    tyre_viscoelastic_coefficient: the paper's ϑ = γ/(1+γ), γ = C_d/(K_d·Δt), referred to the recording's
        sample period Δt. It sets the Maxwell element's relaxation time τ = C_d/K_d = Δt·ϑ/(1-ϑ).
    track_m: wheel track b (axle only). anti_roll_bar_stiffness_N_per_m: K_e (axle only; 0 = no bar).
    """

    model: ModelKind
    mass_kg: float
    spring_stiffness_N_per_m: float
    tyre_stiffness_N_per_m: float
    tyre_viscoelastic_coefficient: float = 0.97
    track_m: float | None = None
    anti_roll_bar_stiffness_N_per_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("mass_kg", "spring_stiffness_N_per_m", "tyre_stiffness_N_per_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.tyre_viscoelastic_coefficient < 1.0:
            raise ValueError("tyre_viscoelastic_coefficient (ϑ) must be in [0, 1)")
        if self.model is ModelKind.AXLE and (self.track_m is None or not self.track_m > 0):
            raise ValueError("an axle needs track_m > 0")
        if self.anti_roll_bar_stiffness_N_per_m < 0:
            raise ValueError("anti_roll_bar_stiffness_N_per_m must be >= 0")

    @property
    def is_axle(self) -> bool:
        return self.model is ModelKind.AXLE

    def maxwell_time_constant_s(self, sample_time_s: float) -> float:
        """τ = C_d/K_d from ϑ (paper eq 5): γ = ϑ/(1-ϑ), τ = γ·Δt."""
        theta = self.tyre_viscoelastic_coefficient
        return sample_time_s * theta / (1.0 - theta)

    @property
    def static_wheel_load_N(self) -> float:
        """Static vertical load on one tyre."""
        wheels = 2 if self.is_axle else 1
        return self.mass_kg * STANDARD_GRAVITY_M_S2 / wheels


PAPER_BENCH = VehicleParameters(
    model=ModelKind.QUARTER_CAR,
    mass_kg=109.3,
    spring_stiffness_N_per_m=14_040.0,
    tyre_stiffness_N_per_m=101_018.0,
    tyre_viscoelastic_coefficient=0.97,
)
"""The paper's motorcycle-fork bench (Table 1, with K_s and K_a put the right way round)."""
