"""Output error: simulate the identified model driven by the measured plate motion and compare the predicted
x_s, x_t with the measured ones. The gap is the RMS over all measured body and wheel channels (metres).

The model is integrated with fixed-step Runge-Kutta at the recording's sample time (the equations of
estimator.dynamics, compiled by estimator.simulation_kernel), starting from the measured (low-passed) state
at the first sample.

A DE refinement of the curve on that gap is offered: the population of candidate models is simulated at
once (one column per candidate), so a generation costs one compiled simulation of all columns.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from estimator.damper import CurveBatch, PiecewiseLinearCurve
from estimator.dynamics import AxlePhysics, CornerPhysics, QuarterCarPhysics, start_state
from estimator.recording import Recording
from estimator.runge_kutta_steps import MAX_SUBSTEPS, model_substeps, sample_substeps
from estimator.signals import Kinematics, initial_state
from estimator.simulation_kernel import integrate_compiled
from estimator.solvers.differential_evolution import DEProgress, DESettings, DifferentialEvolution
from estimator.vehicle import TyreModel, VehicleParameters

REFINE_SETTINGS = DESettings(
    generations=40,
    population_size=24,
    mutation_factor=0.6,
    crossover_probability=0.5,
    mutation_probability=0.0,
)
"""DE settings of the output-error refinement: a short local search around the equation-error solution."""


DIVERGED_GAP_M = 1.0
"""A simulated response this far off the measurement (RMS, m) means the identified model is unstable, e.g. a
negative tyre damping; the gap is then reported as infinite (JSON: null with gap_diverged = true)."""


@dataclass(frozen=True)
class IdentifiedModel:
    """The model as identified: curves (one, or left and right), masses, tyre damping, roll inertia; vehicle
    holds every constant, stated or identified."""

    vehicle: VehicleParameters
    tyre_model: TyreModel
    curves: tuple[PiecewiseLinearCurve, ...]
    sprung_mass_kg: float
    tyre_damping_Ns_per_m: float
    roll_inertia_kg_m2: float | None = None

    @property
    def unsprung_mass_kg(self) -> float:
        """Per wheel."""
        return self.vehicle.unsprung_mass_kg(self.sprung_mass_kg)

    def physics(self, curves: tuple[object, ...] | None = None):
        curves = curves or self.curves

        maxwell = self.tyre_model is TyreModel.MAXWELL
        extra = {"maxwell_time_constant_s": self.vehicle.maxwell_time_constant_s()} if maxwell else {}

        def corner(curve: object) -> CornerPhysics:
            return CornerPhysics(
                damper=curve,  # type: ignore[arg-type]
                spring_stiffness_N_per_m=float(self.vehicle.spring_stiffness_N_per_m),  # type: ignore[arg-type]
                tyre_stiffness_N_per_m=float(self.vehicle.tyre_stiffness_N_per_m),  # type: ignore[arg-type]
                tyre_model=self.tyre_model,
                tyre_damping_Ns_per_m=self.tyre_damping_Ns_per_m,
                **extra,
            )

        if not self.vehicle.is_axle:
            return QuarterCarPhysics(corner(curves[0]), self.sprung_mass_kg, self.unsprung_mass_kg)
        return AxlePhysics(
            corner(curves[0]),
            corner(curves[1]),
            self.sprung_mass_kg,
            self.unsprung_mass_kg,
            float(self.roll_inertia_kg_m2 or 0.0),
            float(self.vehicle.track_m or 0.0),
            self.vehicle.anti_roll_bar_stiffness_N_per_m,
        )


@dataclass(frozen=True)
class OutputErrorResult:
    gap_m: float
    simulated: dict[str, np.ndarray]
    measured: dict[str, np.ndarray]


def measured_drive(
    kin: Mapping[str, Kinematics],
    channels: Mapping[str, np.ndarray],
    sample_time_s: float,
    noise_m: float,
    vehicle: VehicleParameters,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plate drive (position, rate: the low-passed measured plate) and the initial state (each channel's
    start, signals.initial_state, from its readings `channels` with the noise floor noise_m). The model
    doctor drives its simulations with it too (estimator.doctor.simulation), so that validate's gap of a
    diagnosed model is the doctor's."""

    def at0(name: str) -> tuple[float, float]:
        return initial_state(channels[name], sample_time_s, noise_m)

    if not vehicle.is_axle:
        plate, rate = kin["x_r"].position_m, kin["x_r"].velocity_m_s
        return plate, rate, np.array([*at0("x_s"), *at0("x_t"), 0.0])
    plate = np.stack([kin["x_r_l"].position_m, kin["x_r_r"].position_m])
    rate = np.stack([kin["x_r_l"].velocity_m_s, kin["x_r_r"].velocity_m_s])
    (sl, vl), (sr, vr) = at0("x_s_l"), at0("x_s_r")
    b = float(vehicle.track_m)
    state0 = np.array(
        [
            0.5 * (sl + sr),
            0.5 * (vl + vr),
            (sl - sr) / b,
            (vl - vr) / b,
            *at0("x_t_l"),
            *at0("x_t_r"),
            0.0,
            0.0,
        ]
    )
    return plate, rate, state0


def _substeps(
    model: IdentifiedModel,
    curves: tuple[object, ...],
    sample_time_s: float,
    physics: QuarterCarPhysics | AxlePhysics,
    kinematics: Mapping[str, Kinematics],
) -> int:
    """Runge-Kutta steps per sample for the model's fastest decay (runge_kutta_steps.RK4_STABLE_STEP): its
    steepest damper segment (over every column of a population), a Kelvin-Voigt tyre's damping, and the
    force effects its physics carries (a model with effects, estimator.model_io): the smoothed friction
    step, a tyre dashpot and a rig's frame guides, as the doctor counts them
    (estimator.doctor.simulation.substeps). Without the friction, validate simulated a doctor's model with
    461 N of friction on a car at 2 ms at one step per sample, and its gap was 338 µm against the doctor's
    89 µm for the same model (independent pair 111).
    A hysteretic friction's Dahl state decays at |v|/z, v the measured suspension's fastest (kinematics)."""
    kelvin_voigt = model.tyre_model is TyreModel.KELVIN_VOIGT
    # a population (the output-error refinement) carries one tyre damping per column
    dashpot = float(np.max(np.abs(model.tyre_damping_Ns_per_m))) if kelvin_voigt else 0.0
    corners = [physics.corner] if isinstance(physics, QuarterCarPhysics) else [physics.left, physics.right]
    dashpot = max(dashpot, *(float(np.max(np.abs(c.tyre_dashpot_Ns_per_m))) for c in corners))
    # every corner's and column's friction law: the steepest counts (friction.friction_slope_Ns_per_m)
    laws = [
        np.broadcast_arrays(c.coulomb_friction_N, c.stribeck_peak_N, c.stribeck_velocity_m_s) for c in corners
    ]
    friction, stribeck, stribeck_velocity = (
        np.concatenate([np.ravel(law[k]) for law in laws]) for k in range(3)
    )
    presliding = [float(z) for c in corners for z in np.ravel(c.presliding_m) if z > 0]
    hysteresis_rate_per_s = 0.0
    if presliding:
        sides = ("_l", "_r") if model.vehicle.is_axle else ("",)
        speed = [kinematics[f"x_s{s}"].velocity_m_s - kinematics[f"x_t{s}"].velocity_m_s for s in sides]
        hysteresis_rate_per_s = float(np.max(np.abs(speed))) / min(presliding)
    return model_substeps(
        curves,  # type: ignore[arg-type]
        model.sprung_mass_kg,
        model.unsprung_mass_kg,
        2 if model.vehicle.is_axle else 1,
        sample_time_s,
        coulomb_friction_N=friction,
        wheel_dashpot_Ns_per_m=dashpot,
        stribeck_peak_N=stribeck,
        stribeck_velocity_m_s=stribeck_velocity,
        hysteresis_rate_per_s=hysteresis_rate_per_s,
        guide_friction_N=(corners[0].guide_body_friction_N, corners[0].guide_wheel_friction_N),
    )


def sampled_states(
    physics: QuarterCarPhysics | AxlePhysics,
    state0: np.ndarray,
    sample_time_s: float,
    plate: np.ndarray,
    rate: np.ndarray,
    steps: int,
) -> np.ndarray:
    """The states at the samples of a Runge-Kutta run at `steps` steps a sample, from the measured state0
    (dynamics.start_state pads it) driven by the plate's position and rate; all NaN, not simulated, for a
    model stiffer than any damper (more than MAX_SUBSTEPS steps: diverged). Shared with the model doctor's
    batch simulation (estimator.doctor.simulation)."""
    state0 = start_state(physics, state0)
    if steps > MAX_SUBSTEPS:
        return np.full((plate.shape[-1], *state0.shape), np.nan)
    substep_s = sample_time_s / steps
    return integrate_compiled(
        physics, state0, substep_s, sample_substeps(plate, steps), sample_substeps(rate, steps)
    )[::steps]


def simulate_identified(
    model: IdentifiedModel,
    recording: Recording,
    kinematics: Mapping[str, Kinematics],
    noise_m: float,
    curves: tuple[PiecewiseLinearCurve | CurveBatch, ...] | None = None,
    batch: int | None = None,
) -> OutputErrorResult:
    """Drive the model with the measured plate; `kinematics` are the recording's channels low-passed (as
    LinearResiduals.kinematics holds them), noise_m the sensor noise floor (signals.FilterChoice), which
    the initial state is fitted within; `curves` may be CurveBatch objects with `batch` columns."""
    dt = recording.sample_time_s
    plate, rate, state0 = measured_drive(kinematics, recording.channels, dt, noise_m, model.vehicle)
    # beyond its end knots a curve is extended as a damper is (damper.dissipative_table), as the model
    # doctor simulates it: a curve that slopes back at its ends would otherwise push the model away
    physics = model.physics(tuple(c.dissipative() for c in curves or model.curves))
    if batch is not None:
        state0 = np.repeat(state0[:, None], batch, axis=1)
    steps = _substeps(model, curves or model.curves, dt, physics, kinematics)
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable model is reported as a diverged gap
        states = sampled_states(physics, state0, dt, plate, rate, steps)
    outputs = physics.outputs(np.moveaxis(states, 0, 1))
    measured = {name: recording.channels[name] for name in outputs}
    with np.errstate(over="ignore", invalid="ignore"):
        diffs = [outputs[n] - (measured[n][:, None] if batch is not None else measured[n]) for n in outputs]
        gap = np.sqrt(np.mean(np.stack(diffs) ** 2, axis=(0, 1)))
    gap = np.where(np.isfinite(gap) & (gap < DIVERGED_GAP_M), gap, np.inf)
    return OutputErrorResult(gap if batch is not None else float(gap), outputs, measured)


def refine_on_output_error(
    model: IdentifiedModel,
    recording: Recording,
    kinematics: Mapping[str, Kinematics],
    noise_m: float,
    settings: DESettings = REFINE_SETTINGS,
    spread: float = 0.15,
    callback: Callable[[DEProgress], bool | None] | None = None,
    cancel: threading.Event | None = None,
) -> tuple[IdentifiedModel, float]:
    """DE over the curve points and the tyre damping to minimise the output-error gap, searched within
    ±spread (relative, with a floor of 5% of the peak force) around the equation-error solution, which
    seeds the population. Returns the refined model and its gap."""
    grids = [c.velocity_m_s for c in model.curves]
    # a tyre damping the equation error made negative (Kelvin-Voigt on noisy data) starts from 0 instead:
    # the search range is [0, ...], and the start must lie in it
    tyre_start = max(float(model.tyre_damping_Ns_per_m), 0.0)
    start = np.concatenate([*[c.force_N for c in model.curves], [tyre_start]])
    peak = max(float(np.max(np.abs(c.force_N))) for c in model.curves)
    half = np.maximum(spread * np.abs(start), max(0.05 * peak, 1e-6))
    half[-1] = max(spread * abs(start[-1]), 50.0)
    bounds = np.column_stack([start - half, start + half])
    bounds[-1, 0] = max(bounds[-1, 0], 0.0)
    sizes = [g.size for g in grids]

    def gaps(population: np.ndarray) -> np.ndarray:
        p = population.shape[0]
        curves, offset = [], 0
        for grid, size in zip(grids, sizes, strict=True):
            curves.append(CurveBatch(grid, population[:, offset : offset + size].T))
            offset += size
        candidate = replace(model, tyre_damping_Ns_per_m=population[:, -1])
        return simulate_identified(candidate, recording, kinematics, noise_m, tuple(curves), batch=p).gap_m

    result = DifferentialEvolution(gaps, bounds, settings, callback, cancel, initial=start).solve()
    theta, offset, refined_curves = result.theta, 0, []
    for grid, size in zip(grids, sizes, strict=True):
        refined_curves.append(PiecewiseLinearCurve(grid, theta[offset : offset + size]))
        offset += size
    refined = replace(model, curves=tuple(refined_curves), tyre_damping_Ns_per_m=float(theta[-1]))
    return refined, float(result.objective)
