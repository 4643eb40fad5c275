"""Equations of motion of the independent world, with gravity and static preloads written out, on Python
floats (solve_ivp calls the right-hand side once per Runge-Kutta stage).

Positions are upward and measured from the static equilibrium; the spring carries its static preload and the
tyre the static wheel load, so the state at rest is all zeros. Per corner:

    ζ = x_body − x_wheel (suspension extension), ζ' its rate; δ = x_plate − x_wheel (tyre compression)
    suspension force up on the body  F = P_s − K_s·ζ − k3·ζ³ − F_damper − F_c·tanh(ζ'/band)
    tyre force up on the wheel       N = max(0, P_t + K_t·δ + f_m)     (contact cannot pull: lift-off)
    Maxwell element (K_d in series with C_d), in contact   ḟ_m = K_d·(δ' − f_m/C_d)
                                       off the plate       ḟ_m = −K_d·f_m/C_d (it relaxes)
    damper on a compliant top mount k_m (mount deflection y):  F_damper = k_m·y, ẏ = ζ' − v_d(k_m·y),
    v_d the inverse of the damper's force-velocity law; on a rigid mount F_damper = f_d(ζ').

Quarter car: m_s·ẍ_s = −m_s·g + F, m_u·ẍ_u = −m_u·g − F + N.
Axle: heave z and roll φ, body at the wheels x_l = z + (b/2)·φ, x_r = z − (b/2)·φ; the bar adds
−k_e·(ζ_l − ζ_r) to the left suspension force and +k_e·(ζ_l − ζ_r) to the right one;
m_s·z̈ = −m_s·g + F_l + F_r, I·φ̈ = (b/2)·(F_l − F_r), and each wheel as in the quarter car.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from simulators.independent.vehicles import GRAVITY_M_S2, Corner, Vehicle

PlateMotion = Callable[[float], tuple[float, float]]
"""t → (plate position m, plate velocity m/s)."""

CORNER_STATES = 4
"""Per corner: wheel position, wheel velocity, Maxwell force, top-mount deflection."""


@dataclass(frozen=True)
class CornerForces:
    suspension_N: float
    """Up on the body (includes the static preload)."""
    contact_N: float
    """Up on the wheel from the plate; never negative."""
    maxwell_rate_N_s: float
    mount_rate_m_s: float


class CornerLaw:
    """The forces of one corner at one instant (see the module docstring)."""

    def __init__(self, vehicle: Vehicle, corner: Corner) -> None:
        effects = vehicle.effects
        self.spring_preload_N = vehicle.sprung_mass_kg / len(vehicle.corners) * GRAVITY_M_S2
        self.tyre_preload_N = vehicle.static_wheel_load_N(corner)
        self.spring = corner.spring_N_per_m
        self.cubic = effects.cubic_spring_N_per_m3
        self.friction = effects.coulomb_friction_N
        self.band = effects.coulomb_band_m_s
        self.mount = effects.top_mount_N_per_m
        self.tyre = corner.tyre_N_per_m
        self.maxwell_stiffness = corner.maxwell_stiffness_N_per_m
        self.maxwell_damping = corner.maxwell_damping_Ns_per_m
        self.damper = corner.damper

    def forces(
        self,
        body_m: float,
        body_m_s: float,
        wheel_m: float,
        wheel_m_s: float,
        maxwell_N: float,
        mount_m: float,
        plate_m: float,
        plate_m_s: float,
        extra_spring_N: float = 0.0,
    ) -> CornerForces:
        extension = body_m - wheel_m
        rate = body_m_s - wheel_m_s
        if self.mount > 0.0:
            damper = self.mount * mount_m
            mount_rate = rate - self.damper.velocity(damper)
        else:
            damper, mount_rate = self.damper.force(rate), 0.0
        suspension = self.spring_preload_N - self.spring * extension - self.cubic * extension**3 - damper
        if self.friction:
            suspension -= self.friction * math.tanh(rate / self.band)
        suspension -= extra_spring_N
        compression, compression_rate = plate_m - wheel_m, plate_m_s - wheel_m_s
        would_push = self.tyre_preload_N + self.tyre * compression + maxwell_N
        relaxing = -self.maxwell_stiffness * maxwell_N / self.maxwell_damping
        if would_push > 0.0:
            return CornerForces(
                suspension, would_push, self.maxwell_stiffness * compression_rate + relaxing, mount_rate
            )
        return CornerForces(suspension, 0.0, relaxing, mount_rate)


class QuarterCarPhysics:
    """State [x_s, ẋ_s, x_u, ẋ_u, f_m, y_mount]."""

    state_size = 2 + CORNER_STATES

    def __init__(self, vehicle: Vehicle, plate: PlateMotion) -> None:
        if vehicle.is_axle:
            raise ValueError("QuarterCarPhysics needs a quarter car")
        self.corner = vehicle.corners[0]
        self.law = CornerLaw(vehicle, self.corner)
        self.sprung = vehicle.sprung_mass_kg
        self.unsprung = self.corner.unsprung_mass_kg
        self.plate = plate

    def corner_forces(self, t_s: float, state: list[float]) -> list[CornerForces]:
        xs, vs, xu, vu, fm, ym = state
        xr, vr = self.plate(t_s)
        return [self.law.forces(xs, vs, xu, vu, fm, ym, xr, vr)]

    def __call__(self, t_s: float, state: list[float]) -> list[float]:
        (c,) = self.corner_forces(t_s, state)
        _, vs, _, vu, _, _ = state
        return [
            vs,
            c.suspension_N / self.sprung - GRAVITY_M_S2,
            vu,
            (c.contact_N - c.suspension_N) / self.unsprung - GRAVITY_M_S2,
            c.maxwell_rate_N_s,
            c.mount_rate_m_s,
        ]

    @staticmethod
    def body_at_wheels(state: list[float]) -> tuple[float, ...]:
        return (state[0],)

    @staticmethod
    def wheels(state: list[float]) -> tuple[float, ...]:
        return (state[2],)


class AxlePhysics:
    """State [z, ż, φ, φ̇, then per corner (left, right): x_u, ẋ_u, f_m, y_mount]."""

    state_size = 4 + 2 * CORNER_STATES

    def __init__(self, vehicle: Vehicle, plates: tuple[PlateMotion, PlateMotion]) -> None:
        if not vehicle.is_axle:
            raise ValueError("AxlePhysics needs an axle")
        self.laws = [CornerLaw(vehicle, c) for c in vehicle.corners]
        self.unsprung = [c.unsprung_mass_kg for c in vehicle.corners]
        self.sprung = vehicle.sprung_mass_kg
        self.inertia = vehicle.roll_inertia_kg_m2
        self.half_track = 0.5 * vehicle.track_m
        self.bar = vehicle.anti_roll_bar_N_per_m
        self.plates = plates

    def corner_forces(self, t_s: float, state: list[float]) -> list[CornerForces]:
        z, vz, roll, roll_rate = state[:4]
        body = (z + self.half_track * roll, z - self.half_track * roll)
        body_rate = (vz + self.half_track * roll_rate, vz - self.half_track * roll_rate)
        left_wheel, right_wheel = state[4], state[4 + CORNER_STATES]
        bar_N = self.bar * ((body[0] - left_wheel) - (body[1] - right_wheel))
        forces = []
        for side, law in enumerate(self.laws):
            xu, vu, fm, ym = state[4 + side * CORNER_STATES : 4 + (side + 1) * CORNER_STATES]
            xr, vr = self.plates[side](t_s)
            extra = bar_N if side == 0 else -bar_N
            forces.append(law.forces(body[side], body_rate[side], xu, vu, fm, ym, xr, vr, extra))
        return forces

    def __call__(self, t_s: float, state: list[float]) -> list[float]:
        left, right = self.corner_forces(t_s, state)
        rates = [
            state[1],
            (left.suspension_N + right.suspension_N) / self.sprung - GRAVITY_M_S2,
            state[3],
            self.half_track * (left.suspension_N - right.suspension_N) / self.inertia,
        ]
        for side, c in enumerate((left, right)):
            vu = state[4 + side * CORNER_STATES + 1]
            rates += [
                vu,
                (c.contact_N - c.suspension_N) / self.unsprung[side] - GRAVITY_M_S2,
                c.maxwell_rate_N_s,
                c.mount_rate_m_s,
            ]
        return rates

    def body_at_wheels(self, state: list[float]) -> tuple[float, ...]:
        z, roll = state[0], state[2]
        return (z + self.half_track * roll, z - self.half_track * roll)

    @staticmethod
    def wheels(state: list[float]) -> tuple[float, ...]:
        return (state[4], state[4 + CORNER_STATES])
