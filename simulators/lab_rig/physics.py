"""Equations of motion of the lab rig, in absolute heights above the frame's base with gravity and the
springs' free lengths written out (so that static equilibrium is a result, not an assumption), on Python
floats (solve_ivp calls the right-hand side once per Runge-Kutta stage).

State [y_s, ẏ_s, y_u, ẏ_u, f_pad, F_coil, F_cable]:

    ζ = y_s − y_u (suspension length), ζ' its rate; plate height y_r = h_plate + x_r(t)
    δ = L_t − (y_u − y_r) (tyre spring compression), δ' = ẋ_r − ẏ_u
    suspension force up on the body
        S = K_s·(L_s − ζ) − c·ζ' − friction(ζ') + F_coil + cogging(ζ − ζ_rest) − F_cable
    tyre force up on the wheel   T = K_t·δ + f_pad;  pad (Maxwell): ḟ_pad = k_pad·(δ' − f_pad/c_pad)
    m_s·ÿ_s = S − m_s·g − bearing_s(ẏ_s);   m_u·ÿ_u = T − S − m_u·g − bearing_u(ẏ_u)
    coil:   lag·Ḟ_coil = −c_sky·ẏ_s + reference(t) − F_coil
    cable:  Ḟ_cable = σ·(ζ' − |ζ'|·F_cable/F_drag)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simulators.lab_rig.rig import GRAVITY_M_S2, LabRig
from simulators.lab_rig.signals import Signal

STATE_NAMES = ("body_m", "body_m_s", "wheel_m", "wheel_m_s", "pad_N", "coil_N", "cable_N")


@dataclass(frozen=True)
class RigForces:
    """The forces at one instant (N). unrecorded_N: what acts between body and wheel and no file
    records (coil, cogging, cable), up on the body; bearing_*: the frame's friction on body and wheel,
    against their motion."""

    spring_N: float
    damper_N: float
    unrecorded_N: float
    tyre_N: float
    body_bearing_N: float
    wheel_bearing_N: float

    @property
    def suspension_N(self) -> float:
        """Everything between body and wheel, up on the body."""
        return self.spring_N - self.damper_N + self.unrecorded_N


class RigPhysics:
    """The right-hand side of the rig driven by `plate` (x_r in m from its rest height) with the coil
    commanded by `reference` (N) besides its feedback. unrecorded=False leaves out the coil, its cogging
    and the cable (the rig as its data sheet imagines it), for tests that show the force matters."""

    state_size = len(STATE_NAMES)

    def __init__(self, rig: LabRig, plate: Signal, reference: Signal, unrecorded: bool = True) -> None:
        self.rig = rig
        self.plate = plate
        self.reference = reference
        self.unrecorded = unrecorded
        self.rest_body_m, self.rest_wheel_m = rig.static_heights_m()
        self.rest_length_m = self.rest_body_m - self.rest_wheel_m
        self._pad_stiffness = rig.tyre_loss_stiffness_N_per_m

    def rest_state(self) -> list[float]:
        """Static equilibrium: both masses at their rest heights, every internal force zero."""
        return [self.rest_body_m, 0.0, self.rest_wheel_m, 0.0, 0.0, 0.0, 0.0]

    def forces(self, t_s: float, state: list[float]) -> RigForces:
        return self._forces(state, self.plate.motion(t_s)[0])

    def _forces(self, state: list[float], plate_m: float) -> RigForces:
        rig = self.rig
        body, body_rate, wheel, wheel_rate, pad, coil, cable = state
        length, rate = body - wheel, body_rate - wheel_rate
        spring = rig.spring_N_per_m * (rig.spring_free_length_m - length)
        damper = rig.damper_force_N(rate)
        unrecorded = 0.0
        if self.unrecorded:
            act = rig.actuator
            cogging = act.cogging_N * math.sin(
                2.0 * math.pi * (length - self.rest_length_m) / act.cogging_pitch_m
            )
            unrecorded = coil + cogging - cable
        compression = rig.tyre_free_length_m - (wheel - rig.plate_height_m - plate_m)
        tyre = rig.tyre_N_per_m * compression + pad
        return RigForces(
            spring,
            damper,
            unrecorded,
            tyre,
            rig.body_bearing.force(body_rate),
            rig.wheel_bearing.force(wheel_rate),
        )

    def __call__(self, t_s: float, state: list[float]) -> list[float]:
        rig = self.rig
        _, body_rate, _, wheel_rate, pad, coil, cable = state
        plate, plate_rate = self.plate.motion(t_s)
        f = self._forces(state, plate)
        suspension = f.suspension_N
        pad_rate = self._pad_stiffness * ((plate_rate - wheel_rate) - pad / rig.tyre_loss_Ns_per_m)
        coil_rate = cable_rate = 0.0
        if self.unrecorded:
            command = -rig.actuator.skyhook_Ns_per_m * body_rate + self.reference.motion(t_s)[0]
            coil_rate = (command - coil) / rig.actuator.lag_s
            rate = body_rate - wheel_rate
            if rig.cable.level_N > 0.0:
                cable_rate = rig.cable.stiffness_N_per_m * (rate - abs(rate) * cable / rig.cable.level_N)
        return [
            body_rate,
            (suspension - f.body_bearing_N) / rig.sprung_mass_kg - GRAVITY_M_S2,
            wheel_rate,
            (f.tyre_N - suspension - f.wheel_bearing_N) / rig.unsprung_mass_kg - GRAVITY_M_S2,
            pad_rate,
            coil_rate,
            cable_rate,
        ]
