"""Physics simulation of a sweep on the bench: a quarter car or a front axle on the plate(s), integrated
accurately in continuous time, sampled by laser sensors with noise and resolution.

Integration: classical Runge-Kutta with `substeps` steps per sample (default 4, i.e. 0.25 ms at a 1 kHz
recording), the plate motion evaluated exactly at every stage. This is not the estimator's discretisation
(central differences and the backward-Euler Maxwell recursion of eq 4). Damper tables are interpolated by a
monotone cubic (a real damper is smooth; see simulators.dampers.smooth_table).

What the vehicle file would say is `SimulatedVehicle.known`; the rest (mass split, tyre damping, dampers,
roll inertia, hidden effects) is the truth the estimator has to find.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from estimator.damper import PiecewiseLinearCurve, TanhCurve
from estimator.dynamics import AxlePhysics, CornerPhysics, QuarterCarPhysics, integrate_rk4
from estimator.recording import Recording
from estimator.sweep import SweepSettings
from estimator.vehicle import ModelKind, TyreModel, VehicleParameters
from simulators.dampers import smooth_table, valve_damper
from simulators.excitation import plate_motion

Damper = PiecewiseLinearCurve | TanhCurve


@dataclass(frozen=True)
class SensorModel:
    """A laser displacement channel: white Gaussian noise (standard deviation) and quantisation step."""

    noise_m: float = 5e-6
    resolution_m: float = 1e-6

    def measure(self, true_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        noisy = true_m + rng.normal(0.0, self.noise_m, size=np.shape(true_m)) if self.noise_m else true_m
        if self.resolution_m:
            noisy = np.round(noisy / self.resolution_m) * self.resolution_m
        return noisy


@dataclass(frozen=True)
class HiddenEffects:
    """Physical effects beyond the paper's model, off by default (the model doctor looks for them).

    In the model doctor's catalog: coulomb_friction_N (strut and seal friction), cubic_spring_N_per_m3
    (progressive spring, bump stop), tyre_liftoff, channel_delay_s (channel name -> lag, s),
    sensor_offset_m (channel name -> zero error, m), tyre_dashpot_Ns_per_m (a Kelvin-Voigt dashpot in the
    tyre besides whatever SimulatedVehicle.tyre_model says). The tyre's damping is also hidden through
    SimulatedVehicle.tyre_model (a Kelvin-Voigt or Maxwell tyre measured with a model that lacks it), the
    anti-roll bar through a vehicle file without it.

    Outside the catalog (for testing that the doctor says "unexplained"):
    - sensor_gain: channel name -> scale factor of the reading (a laser's calibration error);
    - body_mode_mass_kg, body_mode_frequency_Hz, body_mode_damping_ratio: part of the sprung mass (an
      engine on its mounts) hangs on a spring and damper tuned to that frequency and ratio instead of
      moving rigidly with the body (axle: on the body's heave). The vehicle's total mass is unchanged.
    """

    coulomb_friction_N: float = 0.0
    cubic_spring_N_per_m3: float = 0.0
    tyre_liftoff: bool = False
    channel_delay_s: dict[str, float] = field(default_factory=dict)
    sensor_offset_m: dict[str, float] = field(default_factory=dict)
    tyre_dashpot_Ns_per_m: float = 0.0
    sensor_gain: dict[str, float] = field(default_factory=dict)
    body_mode_mass_kg: float = 0.0
    body_mode_frequency_Hz: float = 12.0
    body_mode_damping_ratio: float = 0.15


@dataclass(frozen=True)
class BodyModePhysics:
    """A vehicle model plus a mass hanging on the body by a spring and a damper (the body's heave):
    state = [the base model's state, x_e, ẋ_e]. The mass is taken out of the base model's sprung mass."""

    base: QuarterCarPhysics | AxlePhysics
    mass_kg: float
    stiffness_N_per_m: float
    damping_Ns_per_m: float

    @property
    def state_size(self) -> int:
        return self.base.state_size + 2

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.base.output_names

    def derivatives(self, state: np.ndarray, plate_m: np.ndarray, plate_rate_m_s: np.ndarray) -> np.ndarray:
        base_state, x_e, v_e = state[:-2], state[-2], state[-1]
        rates = self.base.derivatives(base_state, plate_m, plate_rate_m_s)
        # the body's heave position and velocity are the first two states of both base models
        force = self.stiffness_N_per_m * (x_e - base_state[0]) + self.damping_Ns_per_m * (v_e - base_state[1])
        rates[1] = rates[1] + force / self.base.sprung_mass_kg
        return np.concatenate([rates, np.stack([v_e, -force / self.mass_kg])])

    def outputs(self, state: np.ndarray) -> dict[str, np.ndarray]:
        return self.base.outputs(state[:-2])

    def contact_forces_N(
        self, state: np.ndarray, plate_m: np.ndarray, plate_rate_m_s: np.ndarray
    ) -> dict[str, np.ndarray]:
        return self.base.contact_forces_N(state[:-2], plate_m, plate_rate_m_s)


@dataclass(frozen=True)
class SimulatedVehicle:
    """Truth for a simulated test. For an axle, `dampers` is (left, right) and unsprung mass is per wheel."""

    known: VehicleParameters
    sprung_mass_kg: float
    dampers: tuple[Damper, ...]
    tyre_damping_Ns_per_m: float = 1200.0
    tyre_model: TyreModel = TyreModel.MAXWELL
    roll_inertia_kg_m2: float = 250.0
    effects: HiddenEffects = HiddenEffects()

    @property
    def unsprung_mass_kg(self) -> float:
        return self.known.unsprung_mass_kg(self.sprung_mass_kg)

    def corner(self, damper: Damper, sample_time_s: float) -> CornerPhysics:
        e = self.effects
        return CornerPhysics(
            damper=true_damper(damper),
            spring_stiffness_N_per_m=self.known.spring_stiffness_N_per_m,
            tyre_stiffness_N_per_m=self.known.tyre_stiffness_N_per_m,
            tyre_model=self.tyre_model,
            tyre_damping_Ns_per_m=self.tyre_damping_Ns_per_m,
            maxwell_time_constant_s=self.known.maxwell_time_constant_s(sample_time_s),
            coulomb_friction_N=e.coulomb_friction_N,
            cubic_spring_N_per_m3=e.cubic_spring_N_per_m3,
            tyre_liftoff=e.tyre_liftoff,
            static_wheel_load_N=self.known.static_wheel_load_N,
            tyre_dashpot_Ns_per_m=e.tyre_dashpot_Ns_per_m,
        )

    def physics(self, sample_time_s: float) -> QuarterCarPhysics | AxlePhysics | BodyModePhysics:
        e = self.effects
        rigid_mass = self.sprung_mass_kg - e.body_mode_mass_kg
        base: QuarterCarPhysics | AxlePhysics
        if not self.known.is_axle:
            base = QuarterCarPhysics(
                self.corner(self.dampers[0], sample_time_s), rigid_mass, self.unsprung_mass_kg
            )
        else:
            left, right = self.dampers
            base = AxlePhysics(
                left=self.corner(left, sample_time_s),
                right=self.corner(right, sample_time_s),
                sprung_mass_kg=rigid_mass,
                unsprung_mass_kg=self.unsprung_mass_kg,
                roll_inertia_kg_m2=self.roll_inertia_kg_m2,
                track_m=float(self.known.track_m or 0.0),
                anti_roll_bar_N_per_m=self.known.anti_roll_bar_stiffness_N_per_m,
            )
        if not e.body_mode_mass_kg:
            return base
        omega = 2.0 * np.pi * e.body_mode_frequency_Hz
        return BodyModePhysics(
            base,
            e.body_mode_mass_kg,
            e.body_mode_mass_kg * omega**2,
            2.0 * e.body_mode_damping_ratio * e.body_mode_mass_kg * omega,
        )


def true_damper(damper: Damper) -> Damper:
    """The force-velocity law the simulated damper follows: tanh curves as they are, tables smoothed."""
    return smooth_table(damper) if isinstance(damper, PiecewiseLinearCurve) else damper


@dataclass(frozen=True)
class SimulationSettings:
    """The test: sweep, settling after it, sampling, sensors. right_plate_phase_deg offsets the right plate
    of an axle bench so that both heave and roll are excited."""

    sweep: SweepSettings = field(default_factory=SweepSettings)
    settle_s: float = 1.0
    sample_time_s: float = 0.001
    sensor: SensorModel = SensorModel()
    right_plate_phase_deg: float = 90.0
    seed: int = 0
    substeps: int = 4


@dataclass
class SimulationResult:
    recording: Recording
    truth_states: np.ndarray
    """Noise-free states at the sample times, shape (n_samples, state_size)."""
    truth_contact_force_N: dict[str, np.ndarray]


def default_quarter_car(damper: Damper | None = None) -> SimulatedVehicle:
    """The embedded default: a passenger-car front corner with the valve-model damper and a Maxwell tyre."""
    known = VehicleParameters(
        model=ModelKind.QUARTER_CAR,
        mass_kg=420.0,
        spring_stiffness_N_per_m=26_000.0,
        tyre_stiffness_N_per_m=210_000.0,
        tyre_viscoelastic_coefficient=0.97,
    )
    return SimulatedVehicle(
        known=known, sprung_mass_kg=375.0, dampers=(damper or valve_damper(),), tyre_damping_Ns_per_m=1500.0
    )


def default_axle(
    left: Damper | None = None, right: Damper | None = None, anti_roll_bar_N_per_m: float = 18_000.0
) -> SimulatedVehicle:
    """A passenger-car front axle with an anti-roll bar; the right damper is 15% weaker by default."""
    known = VehicleParameters(
        model=ModelKind.AXLE,
        mass_kg=840.0,
        spring_stiffness_N_per_m=26_000.0,
        tyre_stiffness_N_per_m=210_000.0,
        tyre_viscoelastic_coefficient=0.97,
        track_m=1.5,
        anti_roll_bar_stiffness_N_per_m=anti_roll_bar_N_per_m,
    )
    left = left or valve_damper()
    right = right or valve_damper(
        bleed_Ns_per_m=3800.0,
        blowoff_extension_N=360.0,
        blowoff_compression_N=220.0,
        high_speed_extension_Ns_per_m=1600.0,
    )
    return SimulatedVehicle(
        known=known,
        sprung_mass_kg=750.0,
        dampers=(left, right),
        tyre_damping_Ns_per_m=1500.0,
        roll_inertia_kg_m2=280.0,
    )


def _plates(settings: SimulationSettings, t: np.ndarray, axle: bool) -> tuple[np.ndarray, np.ndarray]:
    if not axle:
        return plate_motion(settings.sweep, t)
    xl, vl = plate_motion(settings.sweep, t)
    xr, vr = plate_motion(settings.sweep, t, phase_offset_rad=np.deg2rad(settings.right_plate_phase_deg))
    return np.stack([xl, xr]), np.stack([vl, vr])


def simulate(
    vehicle: SimulatedVehicle, settings: SimulationSettings = SimulationSettings()
) -> SimulationResult:
    """Integrate the sweep and sample it with the laser sensors."""
    physics = vehicle.physics(settings.sample_time_s)
    axle = vehicle.known.is_axle
    duration = settings.sweep.duration_s + settings.settle_s
    n = round(duration / settings.sample_time_s) + 1
    t = np.arange(n) * settings.sample_time_s
    step = settings.sample_time_s / settings.substeps
    t_half = np.arange(2 * settings.substeps * (n - 1) + 1) * (step / 2)
    plate_half, rate_half = _plates(settings, t_half, axle)
    states = integrate_rk4(
        physics.derivatives, np.zeros(physics.state_size), step, plate_half, rate_half, midpoints_given=True
    )[:: settings.substeps]
    plate, rate = _plates(settings, t, axle)
    outputs = physics.outputs(states.T)
    if axle:
        outputs |= {"x_r_l": plate[0], "x_r_r": plate[1]}
    else:
        outputs |= {"x_r": plate}
    rng = np.random.default_rng(settings.seed)
    channels: dict[str, np.ndarray] = {}
    for name, true in outputs.items():
        delay = vehicle.effects.channel_delay_s.get(name, 0.0)
        if delay:
            true = np.interp(t - delay, t, true, left=true[0])
        true = true * vehicle.effects.sensor_gain.get(name, 1.0)
        true = true + vehicle.effects.sensor_offset_m.get(name, 0.0)
        channels[name] = settings.sensor.measure(true, rng)
    recording = Recording(t, channels, metadata={"source": "simulated", "seed": str(settings.seed)})
    return SimulationResult(recording, states, physics.contact_forces_N(states.T, plate, rate))


def with_effects(vehicle: SimulatedVehicle, **effects: object) -> SimulatedVehicle:
    """A copy of `vehicle` with some hidden effects switched on."""
    return replace(vehicle, effects=replace(vehicle.effects, **effects))
