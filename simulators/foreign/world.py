"""A sweep in the foreign world: integrate the continuous equations (physics.py) with solve_ivp, read the
dense solution through each laser channel (sensors.py), and measure each force effect's share of the
suspension's force (the draws' "size" of a force effect).

The result is the independent world's WorldRecording (so that world's file writer writes it: recording CSV and
vehicle TOML), plus the per-sample forces of the effects.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from simulators.foreign.physics import CORNER_STATES, ForeignVehicle, Physics
from simulators.foreign.sensors import LAG_GRID_DIVISIONS, Channel, FirstOrderLag, MovingAverage
from simulators.independent.excitation import Chirp
from simulators.independent.world import AXLE_NAMES, QUARTER_CAR_NAMES, WorldRecording

MAX_STEP_S = 0.002
"""Longest integration step: keeps the regularised friction sign and the bristle dynamics inside the
explicit method's stability region where the motion is too quiet to limit the step by accuracy. With the
default tolerances a 12 s sweep then takes 2-5 s; against tolerances 1000× tighter the channels differ by
0.1-1 µm (below the 1 µm resolution) except where a stiff bump stop or a hopping wheel makes the motion
sensitive to its history."""
QUANTUM_M = 1e-6


@dataclass(frozen=True)
class StatedErrors:
    """The vehicle file states the (left) spring and tyre rates × these factors."""

    spring_factor: float = 1.0
    tyre_factor: float = 1.0


@dataclass(frozen=True)
class ForeignSettings:
    chirp: Chirp = field(default_factory=Chirp)
    settle_s: float = 1.0
    sample_time_s: float = 0.001
    right_plate_phase_rad: float = math.pi / 2
    relative_tolerance: float = 1e-7
    position_tolerance_m: float = 1e-9
    theta_reference_s: float = 0.001
    """The vehicle file's ϑ is referred to 1 ms whatever the rate (README, vehicle file)."""


@dataclass
class ForeignRecording:
    world: WorldRecording
    effect_forces_N: list[dict[str, np.ndarray]]
    """Per corner: friction, bump, lag_excess (applied damper force − its velocity law), unrecorded and
    suspension (K_s·ζ + f_d(ζ'): the suspension's dynamic force without effects), at the sample instants."""

    def force_share(self, key: str) -> float:
        """RMS of an effect's force over the RMS of the suspension's dynamic force, largest over corners."""
        return max(
            float(np.sqrt(np.mean(c[key] ** 2)) / np.sqrt(np.mean(c["suspension"] ** 2)))
            for c in self.effect_forces_N
        )


def _tolerances(physics: Physics, settings: ForeignSettings) -> np.ndarray:
    """Absolute tolerance per state: positions, velocities (×100 /s), forces (N), lag states."""
    position = settings.position_tolerance_m
    body = [position, 100 * position] * (physics.body_states // 2)
    corner = [position, 100 * position, 1e5 * position, 0.01 * position, 1e5 * position]
    return np.array(body + corner * len(physics.laws))


def channel_names(vehicle: ForeignVehicle) -> tuple[str, ...]:
    return AXLE_NAMES if vehicle.is_axle else QUARTER_CAR_NAMES


def simulate(
    vehicle: ForeignVehicle,
    channels: dict[str, Channel],
    settings: ForeignSettings,
    noise_seed: np.random.SeedSequence | int,
    stated_errors: StatedErrors = StatedErrors(),
) -> ForeignRecording:
    """Integrate the sweep and its settling, read every channel of `channels` (missing ones: plain)."""
    chirps = [settings.chirp]
    if vehicle.is_axle:
        c = settings.chirp
        chirps.append(
            Chirp(
                c.start_Hz,
                c.stop_Hz,
                c.amplitude_m,
                c.duration_s,
                c.fade_s,
                c.phase_rad + settings.right_plate_phase_rad,
            )
        )
    physics = Physics(vehicle, tuple(ch.motion for ch in chirps))
    tolerances = _tolerances(physics, settings)
    if vehicle.forces.damper_lag is not None and vehicle.forces.damper_lag.kind == "series_stiffness":
        tolerances[physics.body_states + 4 :: CORNER_STATES] = settings.position_tolerance_m  # a deflection
    dt = settings.sample_time_s
    samples = round((settings.chirp.duration_s + settings.settle_s) / dt) + 1
    time_s = np.arange(samples) * dt
    solution = solve_ivp(
        lambda t, y: physics(t, y.tolist()),
        (0.0, float(time_s[-1])),
        np.zeros(physics.state_size),
        method="DOP853",
        rtol=settings.relative_tolerance,
        atol=tolerances,
        dense_output=True,
        max_step=MAX_STEP_S,
    )
    if not solution.success:
        raise RuntimeError(f"integration failed: {solution.message}")

    def states_at(t: np.ndarray) -> np.ndarray:
        values = solution.sol(np.clip(t, 0.0, time_s[-1])).T
        values[t < 0.0] = 0.0  # before the sweep the vehicle rests in equilibrium
        return values

    half_track = 0.5 * vehicle.base.track_m
    sides = ("_l", "_r") if vehicle.is_axle else ("",)

    def truth(name: str, t: np.ndarray) -> np.ndarray:
        side = sides.index(name[3:]) if vehicle.is_axle else 0
        if name.startswith("x_r"):
            return np.array([chirps[side].motion(float(x))[0] for x in t])
        states = states_at(t)
        if name.startswith("x_t"):
            return states[:, physics.body_states + side * CORNER_STATES]
        if not vehicle.is_axle:
            return states[:, 0]
        return states[:, 0] + (half_track if side == 0 else -half_track) * states[:, 2]

    names = channel_names(vehicle)
    true = {name: truth(name, time_s) for name in names}
    rng = np.random.default_rng(noise_seed)
    measured: dict[str, np.ndarray] = {}
    for name in names:
        channel = channels.get(name, Channel())
        filtered = true[name]
        if isinstance(channel.filter, FirstOrderLag):
            fine_s = np.arange((samples - 1) * LAG_GRID_DIVISIONS + 1) * (dt / LAG_GRID_DIVISIONS)
            lagged = channel.filter.apply(truth(name, fine_s), dt / LAG_GRID_DIVISIONS)
            filtered = lagged[::LAG_GRID_DIVISIONS]
        elif isinstance(channel.filter, MovingAverage):
            ticks = channel.filter.tick_indices(time_s)
            unique, inverse = np.unique(ticks, return_inverse=True)
            values = truth(name, unique * channel.filter.period_s)
            filtered = values[inverse.reshape(ticks.shape)].mean(axis=1)
        measured[name] = channel.finish(filtered, dt, rng)
    states = states_at(time_s)
    keys = ("friction", "bump", "lag_excess", "unrecorded", "suspension")
    forces = [{k: np.empty(samples) for k in keys} for _ in physics.laws]
    contact = [np.empty(samples) for _ in physics.laws]
    for k, row in enumerate(states):
        for side, f in enumerate(physics.corner_forces(float(time_s[k]), row.tolist())):
            record = forces[side]
            record["friction"][k] = f.friction_N
            record["bump"][k] = f.bump_N
            record["lag_excess"][k] = f.damper_N - f.damper_law_N
            record["unrecorded"][k] = f.unrecorded_N
            record["suspension"][k] = f.spring_dynamic_N + f.damper_law_N
            contact[side][k] = f.contact_N
    stated = vehicle.base.stated(settings.theta_reference_s)
    stated["spring_stiffness_N_per_m"] = round(
        float(stated["spring_stiffness_N_per_m"]) * stated_errors.spring_factor, 1
    )
    stated["tyre_stiffness_N_per_m"] = round(
        float(stated["tyre_stiffness_N_per_m"]) * stated_errors.tyre_factor, 1
    )
    world = WorldRecording(
        time_s,
        measured,
        true,
        contact,
        states,
        stated,
        {"source": "foreign world (simulators/foreign)", "vehicle_kind": vehicle.base.kind},
        int(solution.nfev),
    )
    return ForeignRecording(world, forces)


def measured_sha256(recording: WorldRecording) -> str:
    """The digest of a recording's quantised measured channels (channels_sha256)."""
    return channels_sha256(float(recording.time_s[1] - recording.time_s[0]), recording.measured)


def channels_sha256(sample_time_s: float, channels: dict[str, np.ndarray]) -> str:
    """sha256 of the sample time in µs and the channels in file order, each its name and then its readings in
    whole micrometres as little-endian int64: the same for a recording and for its CSV read back."""
    digest = hashlib.sha256()
    digest.update(f"dt_us={round(sample_time_s * 1e6)}".encode())
    for name, values in channels.items():
        digest.update(name.encode())
        digest.update(np.round(np.asarray(values) / QUANTUM_M).astype("<i8").tobytes())
    return digest.hexdigest()
