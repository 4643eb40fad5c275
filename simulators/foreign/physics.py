"""Equations of motion of the foreign world, on Python floats (solve_ivp calls the right-hand side once per
Runge-Kutta stage). Positions are upward from the static equilibrium; springs and tyres carry their static
preloads, so the state at rest is all zeros. Per corner:

    ζ = x_body − x_wheel, ζ' its rate; δ = x_plate − x_wheel (tyre compression)
    suspension force up on the body   F = P_s − K_s·ζ − F_d + F_friction + F_bump + F_unrecorded − F_bar
    F_d = f_d(ζ') on a plain damper, the lag state's force with a DamperLag (effects.py)
    tyre force up on the wheel        N = max(0, P_t + K_t·δ + f_m)   (a plate cannot pull: lift-off)
    Maxwell element (K_d in series with C_d): ḟ_m = K_d·δ' − f_m/τ on the plate, −f_m/τ off it

Quarter car: m_s·ẍ_s = −m_s·g + F, m_u·ẍ_u = −m_u·g − F + N.
Axle: heave z and roll φ (body at the wheels z ± (b/2)·φ), each side its own wheel, tyre, spring and damper;
the body's centre of mass may sit com_offset_m towards the left wheel, so the sides carry different static
loads: P_s,l/r = m_s·g·(1/2 ± e/b) and I·φ̈ = (b/2)·(F_l − F_r) − m_s·g·e. The anti-roll bar acts on
ζ_l − ζ_r with k_e, up −k_e·(ζ_l − ζ_r) on the left body corner and + on the right.

Corner state [x_u, ẋ_u, f_m, z, q]: z the LuGre bristle deflection, q the damper lag's state (the lagged
force in N for a first-order lag, the series spring's deflection in m for a damper in series).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

from simulators.foreign.effects import ForceEffects
from simulators.independent.vehicles import GRAVITY_M_S2, Corner, Vehicle

PlateMotion = Callable[[float], tuple[float, float]]
CORNER_STATES = 5


@dataclass(frozen=True)
class ForeignVehicle:
    """The truth: masses, per-side corners, bar and track (the independent world's Vehicle, whose own
    `effects` stay off), the force effects, and the body's lateral centre-of-mass offset (axle only)."""

    base: Vehicle
    forces: ForceEffects = field(default_factory=ForceEffects)
    com_offset_m: float = 0.0

    @property
    def is_axle(self) -> bool:
        return self.base.is_axle

    def spring_preloads_N(self) -> tuple[float, ...]:
        weight = self.base.sprung_mass_kg * GRAVITY_M_S2
        if not self.is_axle:
            return (weight,)
        share = self.com_offset_m / self.base.track_m
        return (weight * (0.5 + share), weight * (0.5 - share))


class CornerForces(NamedTuple):
    suspension_N: float
    """Up on the body, static preload included."""
    contact_N: float
    maxwell_rate_N_s: float
    bristle_rate_m_s: float
    lag_rate: float
    damper_N: float
    """The damper's resistance as applied (lagged or not)."""
    damper_law_N: float
    """f_d(ζ'): what a damper without lag would resist."""
    friction_N: float
    bump_N: float
    unrecorded_N: float
    spring_dynamic_N: float
    """K_s·ζ: the spring's force change from static."""


class CornerLaw:
    """The forces of one corner at one instant (see the module docstring)."""

    def __init__(self, corner: Corner, spring_preload_N: float, unsprung_load_N: float, forces: ForceEffects):
        self.spring_preload = spring_preload_N
        self.tyre_preload = spring_preload_N + unsprung_load_N
        self.spring = corner.spring_N_per_m
        self.tyre = corner.tyre_N_per_m
        self.maxwell_stiffness = corner.maxwell_stiffness_N_per_m
        self.relaxation_rate = 1.0 / corner.maxwell_relaxation_s
        self.damper = corner.damper
        self.effects = forces

    def forces(
        self,
        t_s: float,
        body: tuple[float, float],
        wheel: tuple[float, float],
        maxwell_N: float,
        bristle_m: float,
        lag_state: float,
        plate: tuple[float, float],
        bar_N: float = 0.0,
    ) -> CornerForces:
        effects = self.effects
        extension, rate = body[0] - wheel[0], body[1] - wheel[1]
        law_N = self.damper.force(rate)
        lag_rate = 0.0
        lag = effects.damper_lag
        if lag is None:
            damper_N = law_N
        elif lag.kind == "first_order":
            damper_N = lag_state
            lag_rate = (law_N - lag_state) / lag.time_constant_s
        else:
            damper_N = lag.series_stiffness_N_per_m * lag_state
            lag_rate = rate - self.damper.velocity(damper_N)
        friction_N = bristle_rate = 0.0
        if effects.stribeck is not None:
            friction_N += effects.stribeck.force(rate)
        if effects.lugre is not None:
            bristle_rate = effects.lugre.state_rate(bristle_m, rate)
            friction_N += effects.lugre.force(bristle_m, rate)
        bump_N = 0.0
        for stop in effects.bump_stops:
            bump_N += stop.force(extension)
        unrecorded_N = effects.unrecorded.force(t_s) if effects.unrecorded is not None else 0.0
        spring_N = self.spring * extension
        suspension = self.spring_preload - spring_N - damper_N + friction_N + bump_N + unrecorded_N - bar_N
        compression_rate = plate[1] - wheel[1]
        would_push = self.tyre_preload + self.tyre * (plate[0] - wheel[0]) + maxwell_N
        relaxing = -self.relaxation_rate * maxwell_N
        if would_push > 0.0:
            contact, maxwell_rate = would_push, self.maxwell_stiffness * compression_rate + relaxing
        else:
            contact, maxwell_rate = 0.0, relaxing
        return CornerForces(
            suspension,
            contact,
            maxwell_rate,
            bristle_rate,
            lag_rate,
            damper_N,
            law_N,
            friction_N,
            bump_N,
            unrecorded_N,
            spring_N,
        )


class Physics:
    """Quarter car: state [x_s, ẋ_s, corner]; axle: [z, ż, φ, φ̇, left corner, right corner]."""

    def __init__(self, vehicle: ForeignVehicle, plates: tuple[PlateMotion, ...]) -> None:
        base = vehicle.base
        self.axle = vehicle.is_axle
        self.body_states = 4 if self.axle else 2
        self.state_size = self.body_states + CORNER_STATES * len(base.corners)
        self.laws = [
            CornerLaw(c, p, c.unsprung_mass_kg * GRAVITY_M_S2, vehicle.forces)
            for c, p in zip(base.corners, vehicle.spring_preloads_N(), strict=True)
        ]
        self.unsprung = [c.unsprung_mass_kg for c in base.corners]
        self.sprung = base.sprung_mass_kg
        self.inertia = base.roll_inertia_kg_m2
        self.half_track = 0.5 * base.track_m
        self.bar = base.anti_roll_bar_N_per_m if self.axle else 0.0
        self.offset_moment = base.sprung_mass_kg * GRAVITY_M_S2 * vehicle.com_offset_m
        self.plates = plates

    def body_at_wheels(self, state: list[float]) -> list[tuple[float, float]]:
        """(position, velocity) of the body above each wheel."""
        if not self.axle:
            return [(state[0], state[1])]
        z, vz, roll, roll_rate = state[:4]
        h = self.half_track
        return [(z + h * roll, vz + h * roll_rate), (z - h * roll, vz - h * roll_rate)]

    def wheel_positions(self, state: list[float]) -> list[float]:
        return [state[self.body_states + i * CORNER_STATES] for i in range(len(self.laws))]

    def corner_forces(self, t_s: float, state: list[float]) -> list[CornerForces]:
        bodies = self.body_at_wheels(state)
        wheels = [
            state[self.body_states + i * CORNER_STATES : self.body_states + (i + 1) * CORNER_STATES]
            for i in range(len(self.laws))
        ]
        bar_N = 0.0
        if self.axle:
            bar_N = self.bar * ((bodies[0][0] - wheels[0][0]) - (bodies[1][0] - wheels[1][0]))
        forces = []
        for side, law in enumerate(self.laws):
            xu, vu, fm, z, q = wheels[side]
            plate = self.plates[side](t_s)
            forces.append(
                law.forces(t_s, bodies[side], (xu, vu), fm, z, q, plate, bar_N if side == 0 else -bar_N)
            )
        return forces

    def __call__(self, t_s: float, state: list[float]) -> list[float]:
        corners = self.corner_forces(t_s, state)
        if self.axle:
            left, right = corners
            rates = [
                state[1],
                (left.suspension_N + right.suspension_N) / self.sprung - GRAVITY_M_S2,
                state[3],
                (self.half_track * (left.suspension_N - right.suspension_N) - self.offset_moment)
                / self.inertia,
            ]
        else:
            rates = [state[1], corners[0].suspension_N / self.sprung - GRAVITY_M_S2]
        for side, c in enumerate(corners):
            vu = state[self.body_states + side * CORNER_STATES + 1]
            rates += [
                vu,
                (c.contact_N - c.suspension_N) / self.unsprung[side] - GRAVITY_M_S2,
                c.maxwell_rate_N_s,
                c.bristle_rate_m_s,
                c.lag_rate,
            ]
        return rates
