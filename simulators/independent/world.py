"""A sweep in the independent world: integrate the continuous equations with solve_ivp (DOP853 by default,
tight tolerances), sample the dense solution at the sample instants (at t − delay for a lagging channel),
add the zero errors, the noise and the quantisation.

The result carries the measured channels in the project's names (quarter car x_s, x_t, x_r; axle x_s_l,
x_s_r, x_t_l, x_t_r, x_r_l, x_r_r), the noise-free channels, the contact force per corner and the vehicle
file, so a test can check the physics and a benchmark can hand the files to the project.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from simulators.independent.excitation import Chirp
from simulators.independent.physics import AxlePhysics, QuarterCarPhysics
from simulators.independent.sensors import SensorNoise
from simulators.independent.vehicles import Vehicle

QUARTER_CAR_NAMES = ("x_s", "x_t", "x_r")
AXLE_NAMES = ("x_s_l", "x_s_r", "x_t_l", "x_t_r", "x_r_l", "x_r_r")
MAX_STEP_S = 0.001
"""Longest integration step: keeps the narrow band of the friction law (a damping of F_c/band near zero
velocity) inside the explicit method's stability region even where the motion is too quiet to limit the
step by accuracy."""


@dataclass(frozen=True)
class WorldSettings:
    """The test: the plate's chirp, settling after it, sampling, sensors, integration.

    right_plate_phase_rad: the second plate of an axle runs the same chirp shifted by this phase (so roll is
    excited as well as heave); initial_state: None = at rest in static equilibrium; theta_reference_s: the
    sample time the vehicle file's ϑ is referred to: 1 ms whatever the rate, as the README's vehicle file
    says (it was the recording's sample time, an older reading of the README; a 500 Hz recording's file
    then stated ϑ 0.9417 where 0.9700 was meant, a relaxation time half the world's, and the estimator
    took that for a tyre 14-17% stiffer than stated)."""

    chirp: Chirp = field(default_factory=Chirp)
    settle_s: float = 1.0
    sample_time_s: float = 0.001
    noise: SensorNoise = field(default_factory=SensorNoise)
    seed: int = 0
    method: str = "DOP853"
    relative_tolerance: float = 1e-9
    position_tolerance_m: float = 1e-10
    right_plate_phase_rad: float = math.pi / 2
    initial_state: tuple[float, ...] | None = None
    theta_reference_s: float = 0.001


@dataclass
class WorldRecording:
    """A simulated sweep. measured/true: channel name -> samples (m); contact_N: per corner;
    stated: the vehicle file's [vehicle] keys."""

    time_s: np.ndarray
    measured: dict[str, np.ndarray]
    true: dict[str, np.ndarray]
    contact_N: list[np.ndarray]
    states: np.ndarray
    """(samples, states) at the sample instants, noise-free, without delays."""
    stated: dict[str, float | str | bool]
    metadata: dict[str, str]
    solver_evaluations: int

    @property
    def airborne_fraction(self) -> float:
        """Largest fraction, over the corners, of samples with no contact force."""
        return max(float(np.mean(c <= 0.0)) for c in self.contact_N)


def _tolerances(size: int, settings: WorldSettings, axle: bool) -> np.ndarray:
    """Absolute tolerance per state: positions, velocities (×100 /s), forces (N), angles (÷1 m)."""
    position, rate = settings.position_tolerance_m, 100.0 * settings.position_tolerance_m
    force = 1e5 * settings.position_tolerance_m
    body = [position, rate, position, rate] if axle else [position, rate]
    per_corner = [position, rate, force, position]
    return np.array(body + per_corner * ((size - len(body)) // 4))


def simulate(vehicle: Vehicle, settings: WorldSettings = WorldSettings()) -> WorldRecording:
    """Integrate the sweep plus settling and read it with the laser channels."""
    chirps = [settings.chirp]
    if vehicle.is_axle:
        second = Chirp(
            settings.chirp.start_Hz,
            settings.chirp.stop_Hz,
            settings.chirp.amplitude_m,
            settings.chirp.duration_s,
            settings.chirp.fade_s,
            settings.chirp.phase_rad + settings.right_plate_phase_rad,
        )
        chirps.append(second)
    physics: QuarterCarPhysics | AxlePhysics = (
        AxlePhysics(vehicle, (chirps[0].motion, chirps[1].motion))
        if vehicle.is_axle
        else QuarterCarPhysics(vehicle, chirps[0].motion)
    )
    dt = settings.sample_time_s
    end_s = settings.chirp.duration_s + settings.settle_s
    samples = round(end_s / dt) + 1
    time_s = np.arange(samples) * dt
    start = np.zeros(physics.state_size)
    if settings.initial_state is not None:
        start[: len(settings.initial_state)] = settings.initial_state
    solution = solve_ivp(
        lambda t, y: physics(t, y.tolist()),
        (0.0, float(time_s[-1])),
        start,
        method=settings.method,
        rtol=settings.relative_tolerance,
        atol=_tolerances(physics.state_size, settings, vehicle.is_axle),
        dense_output=True,
        max_step=MAX_STEP_S,
    )
    if not solution.success:
        raise RuntimeError(f"integration failed: {solution.message}")

    def state_at(t: np.ndarray) -> np.ndarray:
        inside = np.clip(t, 0.0, time_s[-1])
        values = solution.sol(inside).T
        values[t < 0.0] = start  # before the sweep the vehicle rests where it started
        return values

    names = AXLE_NAMES if vehicle.is_axle else QUARTER_CAR_NAMES
    sides = ("_l", "_r") if vehicle.is_axle else ("",)

    def true_channels(t: np.ndarray) -> dict[str, np.ndarray]:
        states = state_at(t)
        channels: dict[str, np.ndarray] = {}
        rows = [s.tolist() for s in states]
        body = np.array([physics.body_at_wheels(r) for r in rows])
        wheel = np.array([physics.wheels(r) for r in rows])
        for index, side in enumerate(sides):
            channels[f"x_s{side}"] = body[:, index]
            channels[f"x_t{side}"] = wheel[:, index]
            channels[f"x_r{side}"] = np.array([chirps[index].motion(float(x))[0] for x in t])
        return channels

    true = true_channels(time_s)
    states = state_at(time_s)
    rng = np.random.default_rng(settings.seed)
    measured: dict[str, np.ndarray] = {}
    for name in names:
        delay = vehicle.effects.channel_delay_s.get(name, 0.0)
        seen = true_channels(time_s - delay)[name] if delay else true[name]
        seen = seen + vehicle.effects.sensor_offset_m.get(name, 0.0)
        measured[name] = settings.noise.read(seen, rng)
    contact = [np.empty(samples) for _ in sides]
    for k, row in enumerate(states):
        for index, forces in enumerate(physics.corner_forces(float(time_s[k]), row.tolist())):
            contact[index][k] = forces.contact_N
    metadata = {
        "source": "independent world (simulators/independent)",
        "vehicle_kind": vehicle.kind,
        "seed": str(settings.seed),
    }
    return WorldRecording(
        time_s,
        {n: measured[n] for n in names},
        {n: true[n] for n in names},
        contact,
        states,
        vehicle.stated(settings.theta_reference_s),
        metadata,
        int(solution.nfev),
    )
