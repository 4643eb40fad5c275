"""The truth of the independent world: what the vehicle is, what its vehicle file says, and which effects
are hidden in it.

A corner is a wheel (unsprung mass) on a tyre (linear spring in parallel with a Maxwell element: spring K_d
in series with dashpot C_d) under a suspension (linear spring, the damper, and the hidden effects). A
quarter car carries one corner's share of the body; an axle carries a body with heave and roll on two
corners. The vehicle file states the total mass, the spring and tyre stiffness (possibly wrongly: the
stated-stiffness effects), ϑ of the Maxwell tyre referred to the sample time, and for an axle the track and
the anti-roll bar (or omits the bar: the anti_roll_bar effect).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from simulators.independent.dampers import TableDamper

GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class Effects:
    """Hidden effects; all off by default.

    coulomb_friction_N: seal and strut friction, F·tanh(v / coulomb_band_m_s) against the suspension
        velocity (a narrow band, so it is a step in all but name);
    cubic_spring_N_per_m3: a progressive spring, k3·ζ³ added to the linear spring about the static position;
    top_mount_N_per_m: compliance of the damper's top mount, a spring in series with the damper (0 = rigid;
        outside the doctor's catalog);
    channel_delay_s, sensor_offset_m: per channel name (x_s, x_t, x_r, or the axle's names);
    stated_spring_factor, stated_tyre_factor: the vehicle file states truth × factor;
    omit_anti_roll_bar: an axle's vehicle file does not mention its bar.
    Tyre lift-off is not switched: contact never pulls, and a weak enough damper lets the wheel hop.
    """

    coulomb_friction_N: float = 0.0
    coulomb_band_m_s: float = 0.002
    cubic_spring_N_per_m3: float = 0.0
    top_mount_N_per_m: float = 0.0
    channel_delay_s: dict[str, float] = field(default_factory=dict)
    sensor_offset_m: dict[str, float] = field(default_factory=dict)
    stated_spring_factor: float = 1.0
    stated_tyre_factor: float = 1.0
    omit_anti_roll_bar: bool = False


@dataclass(frozen=True)
class Corner:
    """One wheel and its suspension. maxwell_relaxation_s = C_d / K_d of the tyre's Maxwell element."""

    damper: TableDamper
    unsprung_mass_kg: float
    spring_N_per_m: float
    tyre_N_per_m: float
    maxwell_damping_Ns_per_m: float
    maxwell_relaxation_s: float

    @property
    def maxwell_stiffness_N_per_m(self) -> float:
        return self.maxwell_damping_Ns_per_m / self.maxwell_relaxation_s


@dataclass(frozen=True)
class Vehicle:
    """A quarter car (one corner) or an axle (two corners, left then right, same spring and tyre).

    sprung_mass_kg: the body's share carried by the corner(s) under test; roll_inertia_kg_m2, track_m and
    anti_roll_bar_N_per_m matter for an axle only (the bar is a spring on the difference of the left and
    right suspension deflections, equal and opposite on the two sides)."""

    kind: str
    """A word for what it is: "car", "motorcycle", "van", "car axle"."""
    sprung_mass_kg: float
    corners: tuple[Corner, ...]
    effects: Effects = Effects()
    roll_inertia_kg_m2: float = 0.0
    track_m: float = 0.0
    anti_roll_bar_N_per_m: float = 0.0

    def __post_init__(self) -> None:
        if len(self.corners) not in (1, 2):
            raise ValueError("a vehicle has one corner (quarter car) or two (axle)")
        if self.is_axle and not (self.roll_inertia_kg_m2 > 0 and self.track_m > 0):
            raise ValueError("an axle needs a roll inertia and a track")

    @property
    def is_axle(self) -> bool:
        return len(self.corners) == 2

    @property
    def total_mass_kg(self) -> float:
        return self.sprung_mass_kg + sum(c.unsprung_mass_kg for c in self.corners)

    def static_wheel_load_N(self, corner: Corner) -> float:
        return (self.sprung_mass_kg / len(self.corners) + corner.unsprung_mass_kg) * GRAVITY_M_S2

    def stated(self, theta_reference_s: float) -> dict[str, float | str]:
        """The vehicle file, as [vehicle] keys: what the test is told, errors included. ϑ is referred to
        the sample time theta_reference_s (the README: 1 ms, whatever the recording's rate)."""
        corner = self.corners[0]
        relaxation = corner.maxwell_relaxation_s
        stated: dict[str, float | str] = {
            "model": "axle" if self.is_axle else "quarter-car",
            "mass_kg": round(self.total_mass_kg, 3),
            "spring_stiffness_N_per_m": round(corner.spring_N_per_m * self.effects.stated_spring_factor, 1),
            "tyre_stiffness_N_per_m": round(corner.tyre_N_per_m * self.effects.stated_tyre_factor, 1),
            # ϑ = γ/(1+γ), γ = τ/Δt: the Maxwell element's relaxation time in sample periods
            "tyre_viscoelastic_coefficient": round(relaxation / (relaxation + theta_reference_s), 6),
        }
        if self.is_axle:
            stated["track_m"] = self.track_m
            if self.anti_roll_bar_N_per_m and not self.effects.omit_anti_roll_bar:
                stated["anti_roll_bar_stiffness_N_per_m"] = round(self.anti_roll_bar_N_per_m, 1)
        return stated
