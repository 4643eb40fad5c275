"""A run of the lab rig: integrate the equations (physics.py) with solve_ivp, sample the dense solution at
500 Hz, read the three heights with laser-like channels (noise and quantisation: the independent world's
SensorNoise), and write the project's recording CSV and vehicle TOML (the independent world's writer).

The recorded channels are the project's x_s, x_t, x_r: displacements from the rest heights (the lasers
zeroed with the rig at rest), upward positive. What acts between body and wheel without being recorded
(physics.RigForces.unrecorded_N) and the frame's bearing friction are kept beside the recording for tests,
never written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from simulators.independent.files import vehicle_toml_text, write_recording
from simulators.independent.sensors import SensorNoise
from simulators.independent.world import QUARTER_CAR_NAMES, WorldRecording
from simulators.lab_rig.physics import RigPhysics
from simulators.lab_rig.rig import LabRig
from simulators.lab_rig.signals import Signal

SAMPLE_TIME_S = 0.002
"""500 Hz, the lab rig's acquisition rate."""
SOURCE = "lab quarter-car rig (simulators/lab_rig)"


@dataclass(frozen=True)
class RunSpec:
    """One run: the plate's motion, the coil's reference command (the experiment's, unrecorded), how long
    the recording lasts (the input and the settling after it), the seed of its sensor noise, and words.
    metadata: extra '# key: value' lines (the chirp's sweep_start_Hz / sweep_stop_Hz)."""

    name: str
    plate: Signal
    reference: Signal
    duration_s: float
    noise_seed: int
    description: str
    metadata: dict[str, str] = field(default_factory=dict)


@dataclass
class LabRun:
    """A simulated run. recording: what the files hold (measured channels) and the noise-free truth
    (true channels, states at the samples, tyre force in contact_N); unrecorded_N: the force between body
    and wheel no file records (coil, cogging, cable; up on the body); bearing_N: the frame's friction on
    (body, wheel)."""

    spec: RunSpec
    recording: WorldRecording
    unrecorded_N: np.ndarray
    spring_N: np.ndarray
    bearing_N: tuple[np.ndarray, np.ndarray]


def _tolerances() -> np.ndarray:
    """Absolute tolerance per state: heights (m), their rates (m/s), forces (N)."""
    return np.array([1e-10, 1e-8, 1e-10, 1e-8, 1e-7, 1e-7, 1e-7])


def simulate_run(
    rig: LabRig,
    spec: RunSpec,
    noise: SensorNoise,
    sample_time_s: float = SAMPLE_TIME_S,
    unrecorded: bool = True,
) -> LabRun:
    """Integrate the run from rest (static equilibrium) and read it with the laser channels."""
    physics = RigPhysics(rig, spec.plate, spec.reference, unrecorded)
    samples = round(spec.duration_s / sample_time_s) + 1
    time_s = np.arange(samples) * sample_time_s
    solution = solve_ivp(
        lambda t, y: physics(t, y.tolist()),
        (0.0, float(time_s[-1])),
        np.array(physics.rest_state()),
        method="DOP853",
        rtol=1e-8,
        atol=_tolerances(),
        dense_output=True,
        max_step=sample_time_s,
    )
    if not solution.success:
        raise RuntimeError(f"integration failed: {solution.message}")
    states = solution.sol(time_s).T
    plate = np.array([spec.plate.motion(float(t))[0] for t in time_s])
    true = {
        "x_s": states[:, 0] - physics.rest_body_m,
        "x_t": states[:, 2] - physics.rest_wheel_m,
        "x_r": plate,
    }
    forces = [physics.forces(float(t), row.tolist()) for t, row in zip(time_s, states, strict=True)]
    rng = np.random.default_rng(spec.noise_seed)
    measured = {name: noise.read(true[name], rng) for name in QUARTER_CAR_NAMES}
    metadata = {
        "source": SOURCE,
        "run": spec.name,
        "excitation": spec.description,
        "seed": str(spec.noise_seed),
        **spec.metadata,
    }
    recording = WorldRecording(
        time_s,
        measured,
        true,
        [np.array([f.tyre_N for f in forces])],
        states,
        rig.stated(),
        metadata,
        int(solution.nfev),
    )
    return LabRun(
        spec,
        recording,
        np.array([f.unrecorded_N for f in forces]),
        np.array([f.spring_N for f in forces]),
        (np.array([f.body_bearing_N for f in forces]), np.array([f.wheel_bearing_N for f in forces])),
    )


@dataclass(frozen=True)
class RunFiles:
    """A run's recording CSV and its vehicle files: the stated rates (`REC.toml`, the file the CLI finds
    beside REC.csv) and the mass only."""

    csv: Path
    vehicle_toml: Path
    mass_only_toml: Path


def write_run(run: LabRun, rig: LabRig, folder: Path | str, stem: str) -> RunFiles:
    """Write `stem.csv`, `stem.toml` (stated rates, 40-80% off) and `stem.mass-only.toml` in `folder`."""
    base = Path(folder) / stem
    files = RunFiles(base.with_suffix(".csv"), base.with_suffix(".toml"), base.with_suffix(".mass-only.toml"))
    write_recording(run.recording, files.csv, files.vehicle_toml)
    files.mass_only_toml.write_text(vehicle_toml_text(rig.stated(mass_only=True)))
    return files
