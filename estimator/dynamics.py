"""Continuous equations of motion of the quarter car (paper eqs 1-3) and of the front axle (eqs 11-16 with a
physically consistent anti-roll bar), with optional physical effects the model doctor can add.

Sign conventions: displacements upward from static equilibrium; suspension deflection ζ = x_s − x_t;
suspension velocity v = ẋ_s − ẋ_t; tyre deflection δ = x_t − x_r. The suspension force Q (damper + spring
+ effects) pushes the wheel up and the body down, so eq (1) reads M_s·ẍ_s + Q = 0.

The functions work on numpy arrays of any trailing shape, so a whole population of candidate models can be
integrated at once (one column per candidate).

Anti-roll bar (deviation from the paper): eqs (11)-(12) put the bar on the tyre deflection and leave it out
of (13)-(14). Here the bar is a torsion spring on the difference of the left and right suspension
deflections: it adds K_e·(ζ_l − ζ_r) to the left suspension force and subtracts it from the right one, so it
acts with equal and opposite forces on the wheels and on the body: no net heave force, a roll moment.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from estimator.friction import coulomb_sign, hysteresis_rate
from estimator.vehicle import TyreModel

HINGES = 4
"""Most hinges a corner's spring correction has (CornerPhysics.spring_hinge_knots_m): the compiled kernel
carries this many per corner (estimator.simulation_kernel)."""


class ForceCurve(Protocol):
    def force(self, velocity_m_s: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class CornerPhysics:
    """One suspension corner with its tyre.

    tyre_damping_Ns_per_m: C_d; maxwell_time_constant_s: τ = C_d/K_d (Maxwell only).
    Effects (0/False = absent): coulomb_friction_N (strut and seal friction, F_c), cubic_spring_N_per_m3
    (progressive spring / bump stop: + k3·ζ³), tyre_liftoff (contact force cannot go below zero; needs
    static_wheel_load_N), tyre_dashpot_Ns_per_m (a Kelvin-Voigt dashpot in parallel with whatever
    tyre_model says, e.g. beside a Maxwell element).

    Spring hinges (a piecewise-linear correction of the linear spring: a bump or rebound stop with or
    without clearance, a spring stiffer or softer past some deflection): spring_hinge_knots_m and
    spring_hinge_rates_N_per_m, (H,) or (H, columns), H <= HINGES (fewer: pad with rate 0). Hinge k adds
    rate_k·(ζ − knot_k) beyond its knot on the knot's side (ζ > knot_k for knot_k >= 0, ζ < knot_k for
    knot_k < 0) and nothing elsewhere (spring_hinge_force_N). ζ > 0 is extension, so a stop that the
    suspension touches when it is compressed by more than a clearance c (a bump stop) is knot −c, one that
    it touches when extended by more than c (a rebound stop) is knot +c; rate k > 0 stiffens either.

    Stribeck friction: stribeck_peak_N·s(v)·exp(−(v/stribeck_velocity_m_s)²) with s the Coulomb friction's
    smoothed sign (coulomb_sign), so that the friction at low speed is (F_c + peak)·s(v), a static peak
    above the sliding level F_c; a zero peak or velocity (per column) is no Stribeck term.

    Hysteretic friction: with presliding_m z > 0 (per column) the friction's sign s is Dahl's state h
    instead of the smoothed sign of the velocity (hysteresis_rate): after a reversal the force builds up
    over a deflection of about z, tracing a loop in force against deflection, as seal friction does. h is
    one more state per corner (QuarterCarPhysics, AxlePhysics), carried where a column has z > 0.

    Frame guides (a laboratory quarter-car rig whose body and wheel ride on guides fixed to a frame,
    VehicleParameters.frame_guides): guide_body_friction_N and guide_wheel_friction_N, Coulomb friction
    opposing each mass's own velocity against the frame (the smoothed sign, coulomb_sign); quarter car only.

    Every number (and tyre_liftoff) may also be an array of the state's trailing shape, one value per
    column, so that a population of different models is integrated at once (the model doctor does).
    """

    damper: ForceCurve
    spring_stiffness_N_per_m: float
    tyre_stiffness_N_per_m: float
    tyre_model: TyreModel = TyreModel.MAXWELL
    tyre_damping_Ns_per_m: float | np.ndarray = 0.0
    maxwell_time_constant_s: float = 0.032
    coulomb_friction_N: float | np.ndarray = 0.0
    cubic_spring_N_per_m3: float | np.ndarray = 0.0
    tyre_liftoff: bool | np.ndarray = False
    static_wheel_load_N: float = 0.0
    tyre_dashpot_Ns_per_m: float | np.ndarray = 0.0
    spring_hinge_knots_m: np.ndarray | None = None
    spring_hinge_rates_N_per_m: np.ndarray | None = None
    stribeck_peak_N: float | np.ndarray = 0.0
    stribeck_velocity_m_s: float | np.ndarray = 0.0
    presliding_m: float | np.ndarray = 0.0
    guide_body_friction_N: float | np.ndarray = 0.0
    guide_wheel_friction_N: float | np.ndarray = 0.0
    _friction: bool = field(init=False, repr=False, compare=False, default=False)
    _cubic: bool = field(init=False, repr=False, compare=False, default=False)
    _dashpot: bool = field(init=False, repr=False, compare=False, default=False)
    _liftoff_all: bool = field(init=False, repr=False, compare=False, default=False)
    _liftoff_any: bool = field(init=False, repr=False, compare=False, default=False)
    _hinges: tuple[np.ndarray, np.ndarray] | None = field(init=False, repr=False, compare=False, default=None)
    _stribeck: tuple[np.ndarray, np.ndarray] | None = field(
        init=False, repr=False, compare=False, default=None
    )
    hysteretic: bool = field(init=False, repr=False, compare=False, default=False)
    """Some column has hysteretic friction: the corner carries Dahl's state h."""
    guided: bool = field(init=False, repr=False, compare=False, default=False)
    """Some column has friction in the frame guides."""

    def __post_init__(self) -> None:
        # which optional terms are present, decided once (the derivatives are evaluated millions of times)
        flags = {
            "_friction": bool(np.any(self.coulomb_friction_N)),
            "_cubic": bool(np.any(self.cubic_spring_N_per_m3)),
            "_dashpot": bool(np.any(self.tyre_dashpot_Ns_per_m)),
            "_liftoff_all": bool(np.all(self.tyre_liftoff)),
            "_liftoff_any": bool(np.any(self.tyre_liftoff)),
            "_hinges": self._hinge_terms(),
            "_stribeck": self._stribeck_terms(),
            "hysteretic": bool(np.any(np.asarray(self.presliding_m) > 0.0)),
            "guided": bool(np.any(self.guide_body_friction_N) or np.any(self.guide_wheel_friction_N)),
        }
        for name, value in flags.items():
            object.__setattr__(self, name, value)

    def hinge_table(self) -> tuple[np.ndarray, np.ndarray]:
        """(knots, rates), each (HINGES,) or (HINGES, columns): the hinges padded with rate 0 (ValueError,
        one line, for hinges this corner cannot take)."""
        if self.spring_hinge_knots_m is None and self.spring_hinge_rates_N_per_m is None:
            return np.zeros(HINGES), np.zeros(HINGES)
        knots = np.asarray(self.spring_hinge_knots_m, dtype=float)
        rates = np.asarray(self.spring_hinge_rates_N_per_m, dtype=float)
        if knots.shape != rates.shape or knots.ndim not in (1, 2):
            raise ValueError(
                f"spring hinges: knots {knots.shape} and rates {rates.shape} must both be (H,) or (H, cols)"
            )
        if knots.shape[0] > HINGES:
            raise ValueError(f"spring hinges: {knots.shape[0]} given, at most {HINGES}")
        padding = ((0, HINGES - knots.shape[0]),) + ((0, 0),) * (knots.ndim - 1)
        return np.pad(knots, padding), np.pad(rates, padding)

    def _hinge_terms(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(knots, rates) of the hinges that act in some column, or None without any."""
        knots, rates = self.hinge_table()
        acting = np.any(rates != 0.0, axis=tuple(range(1, rates.ndim)))
        return (knots[acting], rates[acting]) if acting.any() else None

    def _stribeck_terms(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(peak, velocity) with the peak 0 where the velocity is (no term there, no division by 0), or None
        where no column has a Stribeck term."""
        velocity = np.asarray(self.stribeck_velocity_m_s, dtype=float)
        absent = velocity == 0.0
        peak = np.where(absent, 0.0, self.stribeck_peak_N)
        return (peak, np.where(absent, 1.0, velocity)) if np.any(peak) else None

    def spring_hinge_force_N(self, deflection_m: np.ndarray) -> np.ndarray | float:
        """The hinges' force at deflection ζ: Σ_k rate_k·(ζ − knot_k) over the hinges whose knot ζ is
        beyond (class docstring); 0.0 without hinges."""
        if self._hinges is None:
            return 0.0
        knots, rates = self._hinges
        zeta = np.asarray(deflection_m)
        # hinge axis first, then the deflection's axes, the columns (if per column) last
        shape = (knots.shape[0], *(1,) * max(0, zeta.ndim - knots.ndim + 1), *knots.shape[1:])
        knots, rates = knots.reshape(shape), rates.reshape(shape)
        excess = zeta - knots
        beyond = np.where(knots >= 0.0, excess > 0.0, excess < 0.0)
        return np.sum(np.where(beyond, rates * excess, 0.0), axis=0)

    def suspension_force_N(
        self, deflection_m: np.ndarray, velocity_m_s: np.ndarray, hysteresis: np.ndarray | float = 0.0
    ) -> np.ndarray:
        """Q: force pushing the wheel up and the body down (damper + spring + friction + progression +
        hinges + Stribeck peak); hysteresis: Dahl's state h (used where presliding_m > 0)."""
        force = self.damper.force(velocity_m_s) + self.spring_stiffness_N_per_m * deflection_m
        # the Stribeck peak steps with the same sign as the Coulomb friction
        sign = 0.0
        if self._friction or self._stribeck is not None:
            sign = coulomb_sign(velocity_m_s)
            if self.hysteretic:
                sign = np.where(np.asarray(self.presliding_m) > 0.0, hysteresis, sign)
        if self._friction:
            force = force + self.coulomb_friction_N * sign
        if self._cubic:
            force = force + self.cubic_spring_N_per_m3 * deflection_m**3
        if self._hinges is not None:
            force = force + self.spring_hinge_force_N(deflection_m)
        if self._stribeck is not None:
            peak, velocity = self._stribeck
            ratio = velocity_m_s / velocity
            force = force + peak * sign * np.exp(-(ratio * ratio))
        return force

    def hysteresis_rate(self, velocity_m_s: np.ndarray, hysteresis: np.ndarray) -> np.ndarray:
        """ḣ of the corner's Dahl state (module function hysteresis_rate)."""
        return hysteresis_rate(velocity_m_s, hysteresis, self.presliding_m)

    def tyre_force_N(
        self, deflection_m: np.ndarray, rate_m_s: np.ndarray, maxwell_force_N: np.ndarray
    ) -> np.ndarray:
        """Dynamic upward force of the plate on the wheel: −K_t·δ − f_v, clipped at liftoff."""
        if self.tyre_model is TyreModel.KELVIN_VOIGT:
            viscous = self.tyre_damping_Ns_per_m * rate_m_s
        elif self.tyre_model is TyreModel.MAXWELL:
            viscous = maxwell_force_N
        else:
            viscous = 0.0
        if self._dashpot:
            viscous = viscous + self.tyre_dashpot_Ns_per_m * rate_m_s
        force = -self.tyre_stiffness_N_per_m * deflection_m - viscous
        if self._liftoff_all:
            force = np.maximum(force, -self.static_wheel_load_N)
        elif self._liftoff_any:
            force = np.where(self.tyre_liftoff, np.maximum(force, -self.static_wheel_load_N), force)
        return force

    def maxwell_rate(
        self, rate_m_s: np.ndarray, maxwell_force_N: np.ndarray, tyre_force_N: np.ndarray | None = None
    ) -> np.ndarray:
        """df_v/dt of eq (3): (C_d/K_d)·ḟ_v + f_v = C_d·δ̇. With tyre_liftoff, while the tyre is off the
        plate (tyre_force_N, this corner's tyre_force_N, at the floor −static load) nothing drives the
        element and it relaxes: (C_d/K_d)·ḟ_v + f_v = 0, as a real tyre's viscoelastic force does in the air.
        Left driven by the wheel's rate, f_v builds up during the flight (the wheel leaves fast) and the tyre
        lands with a force it does not have: on an independent lift-off recording (van, 2.4% airborne) that
        was most of the named model's gap."""
        if self.tyre_model is not TyreModel.MAXWELL:
            return np.zeros_like(maxwell_force_N)
        if tyre_force_N is not None and self._liftoff_any:
            airborne = np.asarray(self.tyre_liftoff) & (tyre_force_N <= -self.static_wheel_load_N)
            rate_m_s = np.where(airborne, 0.0, rate_m_s)
        return (self.tyre_damping_Ns_per_m * rate_m_s - maxwell_force_N) / self.maxwell_time_constant_s


@dataclass(frozen=True)
class QuarterCarPhysics:
    """Quarter car: state = [x_s, ẋ_s, x_t, ẋ_t, f_v], and Dahl's h where the friction is hysteretic."""

    corner: CornerPhysics
    sprung_mass_kg: float
    unsprung_mass_kg: float

    output_names = ("x_s", "x_t")

    @property
    def state_size(self) -> int:
        return 6 if self.corner.hysteretic else 5

    def derivatives(self, state: np.ndarray, plate_m: np.ndarray, plate_rate_m_s: np.ndarray) -> np.ndarray:
        x_s, v_s, x_t, v_t, f_v = state[:5]
        h = state[5] if self.corner.hysteretic else 0.0
        q = self.corner.suspension_force_N(x_s - x_t, v_s - v_t, h)
        tyre = self.corner.tyre_force_N(x_t - plate_m, v_t - plate_rate_m_s, f_v)
        rates = np.empty_like(state)  # filled row by row: cheaper than stacking, this runs every stage
        rates[0] = v_s
        rates[1] = -q / self.sprung_mass_kg
        rates[2] = v_t
        rates[3] = (q + tyre) / self.unsprung_mass_kg
        if self.corner.guided:  # the frame guides' friction, each mass against the frame
            rates[1] -= self.corner.guide_body_friction_N * coulomb_sign(v_s) / self.sprung_mass_kg
            rates[3] -= self.corner.guide_wheel_friction_N * coulomb_sign(v_t) / self.unsprung_mass_kg
        rates[4] = self.corner.maxwell_rate(v_t - plate_rate_m_s, f_v, tyre)
        if self.corner.hysteretic:
            rates[5] = self.corner.hysteresis_rate(v_s - v_t, h)
        return rates

    def outputs(self, state: np.ndarray) -> dict[str, np.ndarray]:
        return {"x_s": state[0], "x_t": state[2]}

    def contact_forces_N(
        self, state: np.ndarray, plate_m: np.ndarray, plate_rate_m_s: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Dynamic tyre force on the wheel (upward positive): the contact force is static load + this."""
        return {"single": self.corner.tyre_force_N(state[2] - plate_m, state[3] - plate_rate_m_s, state[4])}


@dataclass(frozen=True)
class AxlePhysics:
    """Front axle: body heave x_G and roll θ (small angle, θ ≈ (x_s_l − x_s_r)/b), two wheels.

    state = [x_G, ẋ_G, θ, θ̇, x_t_l, ẋ_t_l, x_t_r, ẋ_t_r, f_v_l, f_v_r], and Dahl's h_l, h_r where a corner's
    friction is hysteretic. The plate inputs are stacked (left, right). unsprung_mass_kg is per wheel (the
    paper's M_u^l = M_u^r).
    """

    left: CornerPhysics
    right: CornerPhysics
    sprung_mass_kg: float
    unsprung_mass_kg: float
    roll_inertia_kg_m2: float
    track_m: float
    anti_roll_bar_N_per_m: float = 0.0

    output_names = ("x_s_l", "x_s_r", "x_t_l", "x_t_r")

    def __post_init__(self) -> None:
        if self.left.guided or self.right.guided:
            raise ValueError("frame guides' friction is a quarter-car rig's: an axle has none")

    @property
    def hysteretic(self) -> bool:
        return self.left.hysteretic or self.right.hysteretic

    @property
    def state_size(self) -> int:
        return 12 if self.hysteretic else 10

    def _suspension(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x_g, v_g, roll, roll_rate, x_tl, v_tl, x_tr, v_tr = state[:8]
        h_l, h_r = (state[10], state[11]) if self.hysteretic else (0.0, 0.0)
        half = 0.5 * self.track_m
        zeta_l, zeta_r = x_g + half * roll - x_tl, x_g - half * roll - x_tr
        vel_l, vel_r = v_g + half * roll_rate - v_tl, v_g - half * roll_rate - v_tr
        bar = self.anti_roll_bar_N_per_m * (zeta_l - zeta_r)
        return (
            self.left.suspension_force_N(zeta_l, vel_l, h_l) + bar,
            self.right.suspension_force_N(zeta_r, vel_r, h_r) - bar,
        )

    def derivatives(self, state: np.ndarray, plate_m: np.ndarray, plate_rate_m_s: np.ndarray) -> np.ndarray:
        _, v_g, _, roll_rate, x_tl, v_tl, x_tr, v_tr, fv_l, fv_r = state[:10]
        q_l, q_r = self._suspension(state)
        tyre_l = self.left.tyre_force_N(x_tl - plate_m[0], v_tl - plate_rate_m_s[0], fv_l)
        tyre_r = self.right.tyre_force_N(x_tr - plate_m[1], v_tr - plate_rate_m_s[1], fv_r)
        half = 0.5 * self.track_m
        rates = np.empty_like(state)
        rates[0] = v_g
        rates[1] = -(q_l + q_r) / self.sprung_mass_kg
        rates[2] = roll_rate
        rates[3] = -half * (q_l - q_r) / self.roll_inertia_kg_m2
        rates[4] = v_tl
        rates[5] = (q_l + tyre_l) / self.unsprung_mass_kg
        rates[6] = v_tr
        rates[7] = (q_r + tyre_r) / self.unsprung_mass_kg
        rates[8] = self.left.maxwell_rate(v_tl - plate_rate_m_s[0], fv_l, tyre_l)
        rates[9] = self.right.maxwell_rate(v_tr - plate_rate_m_s[1], fv_r, tyre_r)
        if self.hysteretic:
            rates[10] = self.left.hysteresis_rate(v_g + half * roll_rate - v_tl, state[10])
            rates[11] = self.right.hysteresis_rate(v_g - half * roll_rate - v_tr, state[11])
        return rates

    def outputs(self, state: np.ndarray) -> dict[str, np.ndarray]:
        half = 0.5 * self.track_m
        return {
            "x_s_l": state[0] + half * state[2],
            "x_s_r": state[0] - half * state[2],
            "x_t_l": state[4],
            "x_t_r": state[6],
        }

    def contact_forces_N(
        self, state: np.ndarray, plate_m: np.ndarray, plate_rate_m_s: np.ndarray
    ) -> dict[str, np.ndarray]:
        return {
            "left": self.left.tyre_force_N(state[4] - plate_m[0], state[5] - plate_rate_m_s[0], state[8]),
            "right": self.right.tyre_force_N(state[6] - plate_m[1], state[7] - plate_rate_m_s[1], state[9]),
        }


VehiclePhysics = QuarterCarPhysics | AxlePhysics

Derivatives = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def rk4_step(
    derivatives: Derivatives,
    state: np.ndarray,
    step_s: float,
    plate_m: tuple[np.ndarray, np.ndarray, np.ndarray],
    plate_rate_m_s: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> np.ndarray:
    """One classical Runge-Kutta step; the plate motion is given at the start, middle and end of the step."""
    (p0, pm, p1), (r0, rm, r1) = plate_m, plate_rate_m_s
    k1 = derivatives(state, p0, r0)
    k2 = derivatives(state + 0.5 * step_s * k1, pm, rm)
    k3 = derivatives(state + 0.5 * step_s * k2, pm, rm)
    k4 = derivatives(state + step_s * k3, p1, r1)
    return state + (step_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def integrate_rk4(
    derivatives: Derivatives,
    initial_state: np.ndarray,
    step_s: float,
    plate_m: np.ndarray,
    plate_rate_m_s: np.ndarray,
    midpoints_given: bool = False,
) -> np.ndarray:
    """Fixed-step classical Runge-Kutta driven by a sampled plate motion.

    plate_m, plate_rate_m_s: shape (n,) or (n_plates, n). By default they are sampled at the step times and
    the midpoint values are interpolated linearly (output error, where the plate is a 1 kHz measurement);
    with midpoints_given they are sampled every half step, so n = 2·steps + 1 (the simulator, where the
    plate motion is known exactly). Returns the state at every step, shape (steps + 1, *state.shape).
    """
    if midpoints_given:
        at, mid = plate_m[..., ::2], plate_m[..., 1::2]
        rate_at, rate_mid = plate_rate_m_s[..., ::2], plate_rate_m_s[..., 1::2]
    else:
        at, rate_at = plate_m, plate_rate_m_s
        mid, rate_mid = 0.5 * (at[..., 1:] + at[..., :-1]), 0.5 * (rate_at[..., 1:] + rate_at[..., :-1])
    steps = at.shape[-1] - 1
    states = np.empty((steps + 1, *np.shape(initial_state)))
    state = np.array(initial_state, dtype=float)
    states[0] = state
    h = step_s
    for k in range(steps):
        state = rk4_step(
            derivatives,
            state,
            h,
            (at[..., k], mid[..., k], at[..., k + 1]),
            (rate_at[..., k], rate_mid[..., k], rate_at[..., k + 1]),
        )
        states[k + 1] = state
    return states


def start_state(physics: QuarterCarPhysics | AxlePhysics, measured: np.ndarray) -> np.ndarray:
    """The initial state of a simulation: `measured` (the motion and Maxwell forces at the start, rows
    first, columns for a batch; estimator.output_error.measured_drive) with Dahl's h = 0 appended where the
    physics carries it (a hysteretic friction starts unbuilt)."""
    missing = physics.state_size - measured.shape[0]
    return np.concatenate([measured, np.zeros((missing, *measured.shape[1:]))])
