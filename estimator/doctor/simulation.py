"""Output error of many fitted models at once: each model is driven by the measured plate motion (as its
channel effects correct it) and its predicted sensor readings are compared with the measured ones.

The models become the columns of one population (estimator.dynamics takes arrays of parameters), so one
Runge-Kutta run at the sample time (estimator.simulation_kernel, compiled) simulates them all, as
estimator.output_error does for one model. Every model is written with the general tyre (a Maxwell element
and a parallel dashpot, either of which may be zero), so that models of different structure share one set
of equations.

The gap (m) is the RMS over every measured body and wheel channel of predicted minus measured reading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.damper import CurveBatch
from estimator.doctor.catalog import FRICTION_UNKNOWNS, EffectName
from estimator.doctor.model import FittedModel
from estimator.dynamics import (
    AxlePhysics,
    CornerPhysics,
    QuarterCarPhysics,
    model_substeps,
    sample_substeps,
)
from estimator.output_error import DIVERGED_GAP_M, measured_drive
from estimator.recording import Recording
from estimator.simulation_kernel import integrate_compiled
from estimator.vehicle import TyreModel

MAX_SUBSTEPS = 256
"""Runge-Kutta steps per sample beyond which a model is reported as diverged instead of simulated (substeps):
|λ|·dt above 500, a damper segment steeper than about 10⁶ N·s/m on a motorcycle's wheel at 1 ms, where real
dampers stay below 10⁵. Found on a fresh independent draw (friction 84, a van at 2 ms): the complete model
re-identified with twice the points for the expected gap had knots of 10⁷-10⁸ N at velocities the sweep
hardly reaches, its smooth curve a 2·10¹¹ N·s/m segment, and 4·10⁶ steps per sample asked for 339 GiB. Of
530 cached independent recordings, 5 had a model beyond 256 (377-2470 steps, 10⁶-10⁷ N·s/m; simulated at that
cost before), and one verdict moved: friction 35, where one of the two expected-gap draws now counts as
diverged."""


RUNAWAY_GAP_RATIO = 3.0
"""A model whose gap is at least this many times the RMS of the measured motion it predicts (body and wheel
channels about their means, validate's response_rms_m) has run away, and counts as diverged: predicting no
motion at all would be a third as far off. With the curves extended dissipatively
(estimator.damper.dissipative_table) a model that once grew without bound swings instead, bounded but metres
or tens of millimetres off (the complete models re-identified for the expected gap of three recordings with
a top mount outside the catalog: 44, 274 and 689 mm against motions of a few millimetres)."""


def diverged(residual_m: np.ndarray, measured_m: np.ndarray | None = None) -> bool:
    """A channel's output error (m) from a simulation that diverged: its RMS infinite or at least
    DIVERGED_GAP_M (the bench moves millimetres), or, given the channel's measured readings, at least
    RUNAWAY_GAP_RATIO times their RMS about their mean, as BatchOutputError.gap_m counts a model."""
    limit = DIVERGED_GAP_M
    if measured_m is not None:
        limit = min(limit, RUNAWAY_GAP_RATIO * float(np.std(measured_m)))
    with np.errstate(over="ignore", invalid="ignore"):
        rms = float(np.sqrt(np.mean(np.square(residual_m))))
    return not (np.isfinite(rms) and rms < limit)


@dataclass
class BatchOutputError:
    """Per model (column): predicted readings and their residuals, channel -> (samples, models), m; and the
    RMS of the measured motion each is compared with (response_m, per model)."""

    predicted: dict[str, np.ndarray]
    residual: dict[str, np.ndarray]
    response_m: np.ndarray

    def gap_m(self, samples: np.ndarray | None = None) -> np.ndarray:
        """RMS over all channels of the residual, per model, on the samples where `samples` is True (all
        when None); infinite where a model diverged or ran away (RUNAWAY_GAP_RATIO)."""
        stacked = np.stack([r if samples is None else r[samples] for r in self.residual.values()])
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
        # per model: the stated rates plus the corrections spring_stiffness and tyre_stiffness fitted
        spring_stiffness_N_per_m=np.array([m.spring_stiffness_N_per_m for m in models]),
        tyre_stiffness_N_per_m=np.array([m.tyre_stiffness_N_per_m for m in models]),
        tyre_model=TyreModel.MAXWELL,
        tyre_damping_Ns_per_m=np.array([m.maxwell_damping_Ns_per_m for m in models]),
        maxwell_time_constant_s=vehicle.maxwell_time_constant_s(sample_time_s),
        coulomb_friction_N=each(FRICTION_UNKNOWNS[0]),
        stribeck_peak_N=each(FRICTION_UNKNOWNS[1]),
        stribeck_velocity_m_s=np.array([m.stribeck_velocity_m_s for m in models]),
        spring_hinge_knots_m=np.stack([np.asarray(m.knots_m) for m in models], axis=1),
        spring_hinge_rates_N_per_m=np.stack([m.hinge_rates_N_per_m for m in models], axis=1),
        tyre_liftoff=np.array([m.structure.has(EffectName.TYRE_LIFTOFF) for m in models]),
        static_wheel_load_N=vehicle.static_wheel_load_N,
        tyre_dashpot_Ns_per_m=each("tyre_dashpot_Ns_per_m"),
    )


def _drive(model: FittedModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plate position and rate (the model's corrected plate channel(s), low-passed) and the initial state,
    as validate and identify's output error take them (estimator.output_error.measured_drive)."""
    return measured_drive(
        model.system.kinematics,
        model.signals.recording.channels,
        model.signals.sample_time_s,
        model.system.filters.noise_floor_m,
        model.vehicle,
    )


def substeps(model: FittedModel, sample_time_s: float) -> int:
    """Runge-Kutta steps per sample for the model's fastest decay (estimator.dynamics.decay_rate_per_s):
    its steepest damper segment, its friction and tyre dashpot. The smoothed friction step acts on the wheel
    like a dashpot of F / COULOMB_SMOOTHING_M_S near zero velocity: 207 N on a motorcycle's wheel at 2 ms is
    |λ|·dt of about 5, beyond RK4's stability, and the simulated wheel chattered at every velocity zero (on
    an independent recording with 207 N of friction the friction model's gap was 2.2x the model's without
    it although its equations fitted 12% better)."""
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
    )


def simulate_models(
    models: list[FittedModel], recording: Recording, references: list[Recording | None] | None = None
) -> BatchOutputError:
    """Simulate every model from the measured plate; compare with `recording` (or, per model, with its own
    reference recording where one is given). Models that need more Runge-Kutta steps per sample (substeps)
    are run in their own population, so that every model is simulated the same whatever it is batched with."""
    dt = recording.sample_time_s
    counts = [substeps(m, dt) for m in models]
    if len(set(counts)) == 1:
        return _simulate(models, recording, references, counts[0])
    refs = references or [None] * len(models)
    parts = {}
    for count in sorted(set(counts)):
        chosen = [k for k, c in enumerate(counts) if c == count]
        batch = _simulate([models[k] for k in chosen], recording, [refs[k] for k in chosen], count)
        parts[count] = (chosen, batch)
    order = np.argsort(np.concatenate([parts[c][0] for c in sorted(parts)]), kind="stable")

    def joined(field: str) -> dict[str, np.ndarray]:
        names = getattr(parts[counts[0]][1], field)
        return {
            name: np.concatenate([getattr(parts[c][1], field)[name] for c in sorted(parts)], axis=1)[:, order]
            for name in names
        }

    response = np.concatenate([parts[c][1].response_m for c in sorted(parts)])[order]
    return BatchOutputError(joined("predicted"), joined("residual"), response)


def _simulate(
    models: list[FittedModel], recording: Recording, references: list[Recording | None] | None, steps: int
) -> BatchOutputError:
    """simulate_models for models that share the number of Runge-Kutta steps per sample."""
    vehicle = models[0].vehicle
    dt = recording.sample_time_s
    drives = [_drive(m) for m in models]
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
        if steps > MAX_SUBSTEPS:  # stiffer than any damper: reported as diverged, not simulated
            states = np.full((plate.shape[-1], *state0.shape), np.nan)
        else:
            states = integrate_compiled(
                physics, state0, dt / steps, sample_substeps(plate, steps), sample_substeps(rate, steps)
            )
            states = states[::steps]
        outputs = physics.outputs(np.moveaxis(states, 0, 1))
    predicted: dict[str, np.ndarray] = {}
    residual: dict[str, np.ndarray] = {}
    motion: list[np.ndarray] = []
    for name, simulated in outputs.items():
        columns = []
        for index, model in enumerate(models):
            column = simulated[:, index]
            if not np.all(np.isfinite(column)):
                columns.append(np.full_like(column, np.inf))
                continue
            columns.append(model.corrections.distort(name, column, dt))
        predicted[name] = np.stack(columns, axis=1)
        measured = np.stack(
            [
                (ref if ref is not None else recording).channels[name]
                for ref in (references or [None] * len(models))
            ],
            axis=1,
        )
        with np.errstate(over="ignore", invalid="ignore"):
            residual[name] = predicted[name] - measured
        motion.append(measured - np.mean(measured, axis=0))
    response = np.sqrt(np.mean(np.stack(motion) ** 2, axis=(0, 1)))
    return BatchOutputError(predicted, residual, response)
