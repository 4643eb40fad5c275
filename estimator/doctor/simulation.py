"""Output error of many fitted models driven by the measured plate, as the columns of one population in one
Runge-Kutta run (each with the general tyre: a Maxwell element beside a dashpot). The gap (m) is the RMS
over the body and wheel channels of predicted minus measured reading."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.damper import CurveBatch
from estimator.doctor.catalog import FRICTION_UNKNOWNS, GUIDE_FRICTION_NAMES, EffectName
from estimator.doctor.model import FittedModel
from estimator.dynamics import AxlePhysics, CornerPhysics, QuarterCarPhysics
from estimator.output_error import DIVERGED_GAP_M, measured_drive, sampled_states
from estimator.recording import Recording
from estimator.runge_kutta_steps import model_substeps
from estimator.vehicle import TyreModel

RUNAWAY_GAP_RATIO = 3.0
"""A model whose gap is at least this many times the RMS of the measured motion it predicts (about its
mean) has run away, and counts as diverged: predicting no motion at all would be a third as far off."""


def diverged(residual_m: np.ndarray, measured_m: np.ndarray | None = None) -> bool:
    """A channel's output error (m) from a simulation that diverged: its RMS infinite or at least
    DIVERGED_GAP_M, or RUNAWAY_GAP_RATIO times the RMS of `measured_m` (given), as BatchOutputError.gap_m."""
    limit = DIVERGED_GAP_M
    if measured_m is not None:
        limit = min(limit, RUNAWAY_GAP_RATIO * float(np.std(measured_m)))
    with np.errstate(over="ignore", invalid="ignore"):
        rms = float(np.sqrt(np.mean(np.square(residual_m))))
    return not (np.isfinite(rms) and rms < limit)


@dataclass
class BatchOutputError:
    """Predicted readings and residuals, channel -> (samples, models), m; response_m: per model, the RMS of
    the measured motion it is compared with."""

    predicted: dict[str, np.ndarray]
    residual: dict[str, np.ndarray]
    response_m: np.ndarray

    def gap_m(self) -> np.ndarray:
        """RMS over all channels of the residual, per model; infinite where a model diverged or ran away."""
        stacked = np.stack(list(self.residual.values()))
        with np.errstate(over="ignore", invalid="ignore"):
            gap = np.sqrt(np.mean(stacked**2, axis=(0, 1)))
        limit = np.minimum(DIVERGED_GAP_M, RUNAWAY_GAP_RATIO * self.response_m)
        return np.where(np.isfinite(gap) & (gap < limit), gap, np.inf)

    def column(self, index: int) -> dict[str, np.ndarray]:
        return {name: r[:, index] for name, r in self.residual.items()}


def _corner(models: list[FittedModel], side: int, sample_time_s: float) -> CornerPhysics:
    vehicle = models[0].vehicle
    # one grid for the whole population: the union of every model's knots and a knot a span beyond each
    # end, on which each piecewise-linear curve with its dissipative extension is represented exactly
    grid = np.unique(np.concatenate([m.curves[side].velocity_m_s for m in models]))
    grid = grid[np.concatenate([[True], np.diff(grid) > 1e-9])]
    span = grid[-1] - grid[0]
    grid = np.concatenate([[grid[0] - span], grid, [grid[-1] + span]])
    forces = np.stack([m.curves[side].dissipative().force(grid) for m in models], axis=1)

    def each(name: str) -> np.ndarray:
        return np.array([m.value(name) for m in models])

    return CornerPhysics(
        damper=CurveBatch(grid, forces),
        spring_stiffness_N_per_m=np.array([m.spring_stiffness_N_per_m for m in models]),
        tyre_stiffness_N_per_m=np.array([m.tyre_stiffness_N_per_m for m in models]),
        tyre_model=TyreModel.MAXWELL,
        tyre_damping_Ns_per_m=np.array([m.value("maxwell_damping_Ns_per_m") for m in models]),
        maxwell_time_constant_s=vehicle.maxwell_time_constant_s(sample_time_s),
        coulomb_friction_N=each(FRICTION_UNKNOWNS[0]),
        stribeck_peak_N=each(FRICTION_UNKNOWNS[1]),
        stribeck_velocity_m_s=np.array([m.stribeck_velocity_m_s for m in models]),
        presliding_m=np.array([m.presliding_m for m in models]),
        spring_hinge_knots_m=np.stack([np.asarray(m.knots_m) for m in models], axis=1),
        spring_hinge_rates_N_per_m=np.stack([m.hinge_rates_N_per_m for m in models], axis=1),
        tyre_liftoff=np.array([m.structure.has(EffectName.TYRE_LIFTOFF) for m in models]),
        static_wheel_load_N=vehicle.static_wheel_load_N,
        tyre_dashpot_Ns_per_m=each("tyre_dashpot_Ns_per_m"),
        guide_body_friction_N=each(GUIDE_FRICTION_NAMES[0]),
        guide_wheel_friction_N=each(GUIDE_FRICTION_NAMES[1]),
    )


def substeps(model: FittedModel, sample_time_s: float) -> int:
    """Runge-Kutta steps per sample for the model's fastest decay: its steepest damper segment, its friction
    (near zero velocity a steep dashpot on the wheel), its tyre dashpot, frame guides, Dahl's |v|/z."""
    z, corners = model.presliding_m, model.signals.corners
    speed_m_s = max(float(np.max(np.abs(c.velocity_m_s))) for c in corners) if z else 0.0
    return model_substeps(
        model.curves,
        model.sprung_mass_kg,
        float(model.vehicle.unsprung_mass_kg(model.sprung_mass_kg)),
        2 if model.vehicle.is_axle else 1,
        sample_time_s,
        coulomb_friction_N=model.value(FRICTION_UNKNOWNS[0]),
        wheel_dashpot_Ns_per_m=model.value("tyre_dashpot_Ns_per_m"),
        stribeck_peak_N=model.value(FRICTION_UNKNOWNS[1]),
        stribeck_velocity_m_s=model.stribeck_velocity_m_s,
        hysteresis_rate_per_s=speed_m_s / z if z else 0.0,
        guide_friction_N=(model.value(GUIDE_FRICTION_NAMES[0]), model.value(GUIDE_FRICTION_NAMES[1])),
    )


def simulate_models(
    models: list[FittedModel], recording: Recording, references: list[Recording | None] | None = None
) -> BatchOutputError:
    """Every model driven by the measured plate, compared with `recording` (or its own reference, if given),
    in populations of one number of steps per sample (each is simulated the same whatever its batch)."""
    counts = [substeps(m, recording.sample_time_s) for m in models]
    refs = references or [None] * len(models)
    if len(set(counts)) == 1:  # (joined below, the arrays' layout and so the sums' rounding would differ)
        return _simulate(models, recording, refs, counts[0])
    groups = [[k for k, c in enumerate(counts) if c == count] for count in sorted(set(counts))]
    batches = [
        _simulate([models[k] for k in g], recording, [refs[k] for k in g], counts[g[0]]) for g in groups
    ]
    order = np.argsort(np.concatenate(groups), kind="stable")

    def joined(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        return {name: np.concatenate([p[name] for p in parts], axis=1)[:, order] for name in parts[0]}

    response = np.concatenate([b.response_m for b in batches])[order]
    return BatchOutputError(
        joined([b.predicted for b in batches]), joined([b.residual for b in batches]), response
    )


def _simulate(
    models: list[FittedModel], recording: Recording, references: list[Recording | None], steps: int
) -> BatchOutputError:
    """simulate_models for models that share the number of Runge-Kutta steps per sample."""
    vehicle, dt = models[0].vehicle, recording.sample_time_s
    drives = [
        measured_drive(
            m.system.kinematics,
            m.signals.recording.channels,
            m.signals.sample_time_s,
            m.system.filters.noise_floor_m,
            m.vehicle,
        )
        for m in models
    ]
    axis = 1 if vehicle.is_axle else 0
    plate = np.stack([d[0] for d in drives], axis=axis)
    rate = np.stack([d[1] for d in drives], axis=axis)
    state0 = np.stack([d[2] for d in drives], axis=1)
    sprung = np.array([m.sprung_mass_kg for m in models])
    unsprung = vehicle.unsprung_mass_kg(sprung)
    physics: QuarterCarPhysics | AxlePhysics
    if not vehicle.is_axle:
        physics = QuarterCarPhysics(_corner(models, 0, dt), sprung, unsprung)
    else:
        physics = AxlePhysics(
            _corner(models, 0, dt),
            _corner(models, 1, dt),
            sprung,
            unsprung,
            np.array([m.roll_inertia_kg_m2 or 0.0 for m in models]),
            float(vehicle.track_m or 0.0),
            vehicle.anti_roll_bar_stiffness_N_per_m
            + np.array([m.value("anti_roll_bar_N_per_m") for m in models]),
        )
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable model is reported as a diverged gap
        states = sampled_states(physics, state0, dt, plate, rate, steps)  # NaN: stiffer than any damper
        outputs = physics.outputs(np.moveaxis(states, 0, 1))
    sources = [ref if ref is not None else recording for ref in references]
    predicted: dict[str, np.ndarray] = {}
    residual: dict[str, np.ndarray] = {}
    motion: list[np.ndarray] = []
    for name, simulated in outputs.items():
        columns = [
            m.corrections.distort(name, column, dt)
            if np.all(np.isfinite(column))
            else np.full_like(column, np.inf)
            for m, column in zip(models, simulated.T, strict=True)
        ]
        predicted[name] = np.stack(columns, axis=1)
        measured = np.stack([source.channels[name] for source in sources], axis=1)
        with np.errstate(over="ignore", invalid="ignore"):
            residual[name] = predicted[name] - measured
        motion.append(measured - np.mean(measured, axis=0))
    response = np.sqrt(np.mean(np.stack(motion) ** 2, axis=(0, 1)))
    return BatchOutputError(predicted, residual, response)
