"""Physics sanity of the independent world (simulators/independent, issue 13): it must be right on its own,
since it is what the model doctor is measured against.

- it shares no code with the estimator or the project's simulator (imports only numpy, scipy, the standard
  library and itself);
- at rest it stays in static equilibrium, the tyres carrying the vehicle's weight; displaced, it comes back;
- a linear 2-DOF case (linear damper, Maxwell tyre) follows the matrix-exponential solution, and undamped it
  keeps its energy and oscillates in a mode at the analytic natural frequency;
- the damper interpolant passes through its table points and inverts;
- readings are whole micrometres; AR(1) noise has the requested lag-1 correlation and RMS;
- a 2 ms recording written as CSV is read by the project's reader on a uniform 2 ms grid, with ϑ referred to
  2 ms in the vehicle file;
- a worn damper lets the tyre leave the plate: intervals of zero contact force, never a pulling one.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import eigh, expm

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from simulators.independent.cases import CLASSES, draw_case
from simulators.independent.dampers import (
    DYNO_LOGS,
    TableDamper,
    ValveSide,
    dyno_table,
    suv_table,
    valve_damper,
)
from simulators.independent.excitation import Chirp
from simulators.independent.files import write_recording
from simulators.independent.physics import AxlePhysics, QuarterCarPhysics
from simulators.independent.sensors import SensorNoise
from simulators.independent.vehicles import GRAVITY_M_S2, Corner, Effects, Vehicle
from simulators.independent.world import WorldSettings, simulate

PACKAGE = Path(__file__).resolve().parents[2] / "simulators" / "independent"
QUIET = SensorNoise(0.0, 0.0, 0.0)


def _car(damper: TableDamper | None = None, effects: Effects | None = None) -> Vehicle:
    corner = Corner(damper or suv_table(), 40.0, 26_000.0, 210_000.0, 1500.0, 0.03)
    return Vehicle("car", 380.0, (corner,), effects or Effects())


def _axle() -> Vehicle:
    corners = (
        Corner(suv_table(), 42.0, 26_000.0, 210_000.0, 1500.0, 0.03),
        Corner(suv_table().scaled(0.7), 42.0, 26_000.0, 210_000.0, 1500.0, 0.03),
    )
    return Vehicle(
        "car axle", 760.0, corners, roll_inertia_kg_m2=300.0, track_m=1.5, anti_roll_bar_N_per_m=1.5e4
    )


def _linear_damper(damping_Ns_per_m: float) -> TableDamper:
    return TableDamper("linear", np.array([-1.0, 0.0, 1.0]), np.array([-1.0, 0.0, 1.0]) * damping_Ns_per_m)


def test_imports_nothing_of_the_project_outside_itself() -> None:
    allowed = {"numpy", "scipy", "simulators", "__future__"}
    for path in PACKAGE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            modules = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            for module in modules:
                top = module.split(".")[0]
                if top == "simulators":
                    assert module.startswith("simulators.independent"), f"{path.name} imports {module}"
                else:
                    assert top in allowed or top in _stdlib(), f"{path.name} imports {module}"


def _stdlib() -> set[str]:
    import sys

    return set(sys.stdlib_module_names)


@pytest.mark.parametrize("vehicle", [_car(effects=Effects(150.0, 0.002, 4e8)), _axle()], ids=["car", "axle"])
def test_at_rest_it_stays_in_static_equilibrium_on_its_weight(vehicle: Vehicle) -> None:
    still = Chirp(amplitude_m=0.0, duration_s=1.0)
    physics = (
        AxlePhysics(vehicle, (still.motion, still.motion))
        if vehicle.is_axle
        else QuarterCarPhysics(vehicle, still.motion)
    )
    rates = physics(0.5, [0.0] * physics.state_size)
    assert np.max(np.abs(rates)) < 1e-12
    world = simulate(vehicle, WorldSettings(chirp=still, settle_s=0.5, noise=QUIET))
    assert np.max(np.abs(world.states)) < 1e-12  # positions (m), velocities (m/s), forces (N)
    total_contact = sum(c[-1] for c in world.contact_N)
    assert total_contact == pytest.approx(vehicle.total_mass_kg * GRAVITY_M_S2, rel=1e-12)


def test_displaced_it_comes_back_to_the_static_position() -> None:
    world = simulate(
        _car(),
        WorldSettings(
            chirp=Chirp(amplitude_m=0.0, duration_s=1.0), settle_s=4.0, noise=QUIET, initial_state=(0.01,)
        ),
    )
    assert abs(world.true["x_s"][0]) == pytest.approx(0.01)
    assert np.max(np.abs(world.states[-1, :4])) < 1e-6  # positions and velocities


def _linear_matrices(vehicle: Vehicle, damping: float) -> np.ndarray:
    """State matrix of [x_s, v_s, x_u, v_u, f_m] for the linear quarter car on a plate at rest."""
    corner = vehicle.corners[0]
    ms, mu = vehicle.sprung_mass_kg, corner.unsprung_mass_kg
    ks, kt = corner.spring_N_per_m, corner.tyre_N_per_m
    kd, cd = corner.maxwell_stiffness_N_per_m, corner.maxwell_damping_Ns_per_m
    return np.array(
        [
            [0, 1, 0, 0, 0],
            [-ks / ms, -damping / ms, ks / ms, damping / ms, 0],
            [0, 0, 0, 1, 0],
            [ks / mu, damping / mu, -(ks + kt) / mu, -damping / mu, 1 / mu],
            [0, 0, 0, -kd, -kd / cd],
        ]
    )


def test_linear_free_response_follows_the_matrix_exponential() -> None:
    damping = 1800.0
    vehicle = _car(_linear_damper(damping))
    start = np.array([0.004, 0.0, -0.001, 0.0, 0.0])
    world = simulate(
        vehicle,
        WorldSettings(
            chirp=Chirp(amplitude_m=0.0, duration_s=1.0),
            settle_s=2.0,
            noise=QUIET,
            initial_state=tuple(start),
        ),
    )
    matrix = _linear_matrices(vehicle, damping)
    exact = np.array([expm(matrix * t) @ start for t in world.time_s[::50]])
    assert np.max(np.abs(world.states[::50, :2] - exact[:, :2])) < 1e-8
    assert np.max(np.abs(world.states[::50, 2:4] - exact[:, 2:4])) < 1e-8
    assert np.max(np.abs(world.true["x_s"][-1])) < 2e-5  # and it decays


def test_undamped_it_keeps_its_energy_and_rings_at_the_natural_frequency() -> None:
    vehicle = _car(_linear_damper(1e-9))
    vehicle = Vehicle(
        "car", 380.0, (Corner(vehicle.corners[0].damper, 40.0, 26_000.0, 210_000.0, 1e-9, 1.0),)
    )
    corner = vehicle.corners[0]
    mass = np.diag([vehicle.sprung_mass_kg, corner.unsprung_mass_kg])
    stiffness = np.array(
        [
            [corner.spring_N_per_m, -corner.spring_N_per_m],
            [-corner.spring_N_per_m, corner.spring_N_per_m + corner.tyre_N_per_m],
        ]
    )
    eigenvalues, modes = eigh(stiffness, mass)
    body_mode = modes[:, 0] / modes[0, 0] * 0.005
    settings = WorldSettings(
        chirp=Chirp(amplitude_m=0.0, duration_s=1.0),
        settle_s=3.0,
        noise=QUIET,
        initial_state=(body_mode[0], 0.0, body_mode[1], 0.0),
    )
    world = simulate(vehicle, settings)
    omega = math.sqrt(eigenvalues[0])
    assert 0.8 < omega / (2 * math.pi) < 2.0  # a body mode of a car
    np.testing.assert_allclose(world.true["x_s"], 0.005 * np.cos(omega * world.time_s), atol=1e-8)
    velocities = world.states[:, [1, 3]]
    positions = world.states[:, [0, 2]]
    energy = 0.5 * np.einsum("ni,ij,nj->n", velocities, mass, velocities) + 0.5 * np.einsum(
        "ni,ij,nj->n", positions, stiffness, positions
    )
    assert np.max(np.abs(energy / energy[0] - 1.0)) < 1e-7


@pytest.mark.parametrize(
    "damper",
    [
        suv_table(),
        dyno_table(DYNO_LOGS[0]),
        dyno_table(DYNO_LOGS[1]),
        valve_damper(ValveSide(9000, 2e4, 700, 3e-5), ValveSide(4000, 8e3, 350, 5e-5)),
    ],
    ids=["suv", "dyno-s5", "dyno-s6", "valve"],
)
def test_the_damper_interpolant_passes_through_its_table_and_inverts(damper: TableDamper) -> None:
    forces = [damper.force(float(v)) for v in damper.velocity_m_s]
    np.testing.assert_allclose(forces, damper.force_N, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(damper.interpolant(damper.velocity_m_s), damper.force_N, rtol=1e-12, atol=1e-9)
    lo, hi = damper.velocity_m_s[0], damper.velocity_m_s[-1]
    inside = np.linspace(lo, hi, 997)
    np.testing.assert_allclose(
        [damper.force(float(v)) for v in inside], damper.interpolant(inside), rtol=1e-12, atol=1e-9
    )
    dense = np.linspace(2 * lo, 2 * hi, 2001)
    force = np.array([damper.force(float(v)) for v in dense])
    assert np.all(np.diff(force) > 0)  # monotone, also where it is extended beyond the table
    back = [damper.velocity(float(f)) for f in force]
    np.testing.assert_allclose(back, dense, atol=1e-9)


def test_readings_are_whole_micrometres() -> None:
    world = simulate(
        _car(), WorldSettings(chirp=Chirp(duration_s=1.0), settle_s=0.2, noise=SensorNoise(4e-6, 0.5, 1e-6))
    )
    for name, reading in world.measured.items():
        steps = reading / 1e-6
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-6, err_msg=name)
        assert np.std(reading - world.true[name]) == pytest.approx(4e-6, rel=0.25)


def test_ar1_noise_has_the_requested_lag1_correlation_and_rms() -> None:
    for rho in (0.0, 0.4, 0.85):
        noise = SensorNoise(6e-6, rho, 0.0).noise(400_000, np.random.default_rng(7))
        lag1 = float(np.corrcoef(noise[:-1], noise[1:])[0, 1])
        assert lag1 == pytest.approx(rho, abs=0.01)
        assert float(np.sqrt(np.mean(noise**2))) == pytest.approx(6e-6, rel=0.02)


@pytest.mark.parametrize("theta_reference_s", [0.002, 0.001], ids=["theta-at-2ms", "theta-at-1ms"])
def test_a_2_ms_recording_is_read_on_a_uniform_2_ms_grid(tmp_path: Path, theta_reference_s: float) -> None:
    settings = WorldSettings(
        chirp=Chirp(duration_s=2.0), settle_s=0.3, sample_time_s=0.002, theta_reference_s=theta_reference_s
    )
    world = simulate(_car(), settings)
    write_recording(world, tmp_path / "rec.csv", tmp_path / "car.toml")
    recording = read_recording_csv(tmp_path / "rec.csv")
    assert recording.sample_time_s == pytest.approx(0.002)
    np.testing.assert_allclose(np.diff(recording.time_s), 0.002, atol=1e-9)
    assert recording.time_s.size == world.time_s.size
    for name, reading in world.measured.items():
        np.testing.assert_allclose(recording.channels[name], reading, atol=1e-12)
    vehicle = read_vehicle(tmp_path / "car.toml")
    theta = vehicle.tyre_viscoelastic_coefficient
    assert theta_reference_s * theta / (1.0 - theta) == pytest.approx(0.03, rel=1e-4)  # τ = Δt·ϑ/(1 − ϑ)
    assert vehicle.mass_kg == pytest.approx(420.0)


def test_a_worn_damper_lets_the_tyre_leave_the_plate() -> None:
    chirp = Chirp(start_Hz=8.0, stop_Hz=20.0, duration_s=3.0)
    worn = simulate(_car(suv_table().scaled(0.05)), WorldSettings(chirp=chirp, settle_s=0.2, noise=QUIET))
    contact = worn.contact_N[0]
    assert np.min(contact) == 0.0  # never negative: the plate cannot pull
    airborne = contact == 0.0
    starts = np.flatnonzero(np.diff(airborne.astype(int)) == 1)
    ends = np.flatnonzero(np.diff(airborne.astype(int)) == -1)
    assert starts.size >= 3  # it hops repeatedly
    assert np.max(ends[: starts.size] - starts[: ends.size]) >= 3  # for whole intervals, not single samples
    healthy = simulate(_car(), WorldSettings(chirp=chirp, settle_s=0.2, noise=QUIET))
    assert np.min(healthy.contact_N[0]) > 0.0


def test_cases_of_every_class_are_drawn_reproducibly() -> None:
    for label in CLASSES:
        first, again = draw_case(label, 1), draw_case(label, 1)
        assert first.description == again.description
        assert first.vehicle.is_axle == (label == "anti_roll_bar")
        assert (first.hidden == ()) == (label == "clean")


def test_an_axle_carries_the_same_wheel_and_tyre_on_both_sides() -> None:
    """Left and right of one axle are mirror images (the estimator's axle, as the paper's, has one unsprung
    mass and one tyre damping): only the dampers differ."""
    for seed in range(5):
        left, right = draw_case("anti_roll_bar", seed).vehicle.corners
        assert left.unsprung_mass_kg == right.unsprung_mass_kg
        assert left.maxwell_damping_Ns_per_m == right.maxwell_damping_Ns_per_m
        assert left.maxwell_relaxation_s == right.maxwell_relaxation_s
        assert (left.spring_N_per_m, left.tyre_N_per_m) == (right.spring_N_per_m, right.tyre_N_per_m)
