"""The lab quarter-car rig world (simulators/lab_rig, issue 29 item 5) is what it claims to be:

- it imports nothing from estimator/, drivers/, daq/ or service/ (from simulators only itself and the
  independent world's generic pieces);
- at rest it sits in static equilibrium, the springs carrying the weights; without losses it keeps its
  energy;
- the vehicle file states the spring and tyre rates 40-80% off, above and below, and the true total mass;
  the mass-only file states the mass only;
- a force acts between body and wheel that changes the motion and that neither file records;
- runs are sampled at 500 Hz, read with the drawn laser noise (level, colour) in whole micrometres;
- a rig's runs differ in their inputs, the coil's command and their noise.

Random cases from fixed seeds; each simulated run is a few seconds long.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from simulators.lab_rig.draws import RigDraw, draw_rig
from simulators.lab_rig.physics import RigPhysics
from simulators.lab_rig.rig import GRAVITY_M_S2, NO_FRICTION, Actuator, CableDrag, LabRig
from simulators.lab_rig.signals import Still
from simulators.lab_rig.world import LabRun, RunSpec, simulate_run, write_run

PACKAGE = Path(__file__).resolve().parents[2] / "simulators" / "lab_rig"
SEEDS = range(200)
FIXTURE_SEED = 7
"""A rig with coloured noise (ρ 0.75) and both rates stated too low."""
RUN_S = 2.5


def _factor_ranges_hold(factor: float) -> bool:
    return 0.2 - 1e-9 <= factor <= 0.6 + 1e-9 or 1.4 - 1e-9 <= factor <= 1.8 + 1e-9


@pytest.fixture(scope="module")
def draw() -> RigDraw:
    return draw_rig(FIXTURE_SEED, run_s=RUN_S)


@pytest.fixture(scope="module")
def run_a(draw: RigDraw) -> LabRun:
    return draw.simulate("A")


def test_imports_nothing_of_the_project_but_itself_and_the_independent_worlds_pieces() -> None:
    allowed_simulators = {"simulators.lab_rig", "simulators.independent"}
    seen = set()
    for path in PACKAGE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                modules = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                modules = [node.module or ""]
            else:
                continue
            for module in modules:
                top = module.split(".")[0]
                assert top not in {"estimator", "drivers", "daq", "service"}, f"{path.name} imports {module}"
                if top == "simulators":
                    assert ".".join(module.split(".")[:2]) in allowed_simulators, f"{path.name}: {module}"
                seen.add(module)
    assert "scipy.integrate" in seen  # solve_ivp integrates it


def test_at_rest_it_sits_in_static_equilibrium_the_springs_carrying_the_weights() -> None:
    for seed in range(20):
        rig = draw_rig(seed, run_s=RUN_S).rig
        physics = RigPhysics(rig, Still(), Still())
        rest = physics.rest_state()
        assert np.max(np.abs(physics(0.0, rest))) < 1e-9
        forces = physics.forces(0.0, rest)
        assert forces.spring_N == pytest.approx(rig.sprung_mass_kg * GRAVITY_M_S2, rel=1e-12)
        assert forces.tyre_N == pytest.approx(rig.total_mass_kg * GRAVITY_M_S2, rel=1e-12)
        assert forces.unrecorded_N == 0.0
    rig = draw_rig(FIXTURE_SEED, run_s=RUN_S).rig
    still = simulate_run(rig, RunSpec("rest", Still(), Still(), 1.0, 0, "at rest"), draw_rig(0).noise)
    for name in ("x_s", "x_t", "x_r"):
        assert np.max(np.abs(still.recording.true[name])) < 1e-12


def test_the_damper_it_applies_is_the_rigs_damper_force_and_opposes_the_rate() -> None:
    """LabRig.damper_force_N is what benchmarks hold a model's damper curve against: it must be the force
    the physics applies between body and wheel, and a damper (it takes energy out at every rate)."""
    for seed in range(5):
        rig = draw_rig(seed, run_s=RUN_S).rig
        physics = RigPhysics(rig, Still(), Still())
        for rate_m_s in (-0.3, -0.01, -1e-4, 1e-4, 0.02, 0.5):
            state = physics.rest_state()
            state[1] = rate_m_s  # the body moving, the wheel still: the suspension's rate is the body's
            applied = physics.forces(0.0, state).damper_N
            assert applied == rig.damper_force_N(rate_m_s)
            assert applied * rate_m_s > 0.0  # subtracted from the body's force: against the motion


def test_without_losses_it_keeps_its_energy() -> None:
    """The signs of gravity, springs and the tyre: released 2 mm above rest, a lossless rig neither gains
    nor loses energy."""
    rig = LabRig(2.5, 1.0, 900.0, 2500.0, 1e-9, 0.005, 0.0, NO_FRICTION, Actuator(0.0, 0.002, 0.0, 0.01),
                 CableDrag(0.0, 0.0), NO_FRICTION, NO_FRICTION, 1.5, 0.5)  # fmt: skip
    physics = RigPhysics(rig, Still(), Still())
    start = physics.rest_state()
    start[0] += 0.002

    def energy(y: np.ndarray) -> float:
        spring = rig.spring_free_length_m - (y[0] - y[2])
        tyre = rig.tyre_free_length_m - (y[2] - rig.plate_height_m)
        kinetic = 0.5 * rig.sprung_mass_kg * y[1] ** 2 + 0.5 * rig.unsprung_mass_kg * y[3] ** 2
        elastic = 0.5 * rig.spring_N_per_m * spring**2 + 0.5 * rig.tyre_N_per_m * tyre**2
        return kinetic + elastic + GRAVITY_M_S2 * (rig.sprung_mass_kg * y[0] + rig.unsprung_mass_kg * y[2])

    solution = solve_ivp(lambda t, y: physics(t, y.tolist()), (0.0, 2.0), start, rtol=1e-10, atol=1e-12)
    energies = np.array([energy(y) for y in solution.y.T])
    exchanged = 0.5 * rig.spring_N_per_m * 0.002**2  # the energy of the release, for scale
    assert np.max(np.abs(energies - energies[0])) < 1e-4 * exchanged
    assert np.ptp(solution.y[0]) > 0.003  # it does oscillate


def test_the_stated_rates_are_40_to_80_percent_off_above_and_below() -> None:
    spring, tyre = [], []
    for seed in SEEDS:
        rig = draw_rig(seed, run_s=RUN_S).rig
        spring.append(rig.stated_spring_factor)
        tyre.append(rig.stated_tyre_factor)
        stated = rig.stated()
        assert stated["spring_stiffness_N_per_m"] == pytest.approx(rig.spring_N_per_m * spring[-1], abs=0.05)
        assert stated["tyre_stiffness_N_per_m"] == pytest.approx(rig.tyre_N_per_m * tyre[-1], abs=0.05)
    for factors in (spring, tyre):
        assert all(_factor_ranges_hold(f) for f in factors)
        assert sum(f < 1.0 for f in factors) > 0.3 * len(factors)
        assert sum(f > 1.0 for f in factors) > 0.3 * len(factors)
    assert np.corrcoef(spring, tyre)[0, 1] < 0.3  # drawn apart


def test_the_files_state_wrong_rates_and_the_true_mass_and_nothing_of_the_unrecorded_force(
    draw: RigDraw, run_a: LabRun, tmp_path: Path
) -> None:
    files = write_run(run_a, draw.rig, tmp_path, "rig_A")
    rig = draw.rig
    vehicle, mass_only = read_vehicle(files.vehicle_toml), read_vehicle(files.mass_only_toml)
    assert vehicle.mass_kg == pytest.approx(rig.total_mass_kg, rel=1e-4)
    assert _factor_ranges_hold(vehicle.spring_stiffness_N_per_m / rig.spring_N_per_m)
    assert _factor_ranges_hold(vehicle.tyre_stiffness_N_per_m / rig.tyre_N_per_m)
    assert mass_only.mass_kg == vehicle.mass_kg
    assert mass_only.spring_stiffness_N_per_m is None and mass_only.tyre_stiffness_N_per_m is None
    assert set(tomllib.loads(files.vehicle_toml.read_text())["vehicle"]) == {
        "model",
        "mass_kg",
        "spring_stiffness_N_per_m",
        "tyre_stiffness_N_per_m",
        "frame_guides",  # a fact of the rig the lab knows (its masses ride on guides), not of its forces
    }
    assert set(tomllib.loads(files.mass_only_toml.read_text())["vehicle"]) == {
        "model",
        "mass_kg",
        "frame_guides",
    }
    assert vehicle.frame_guides and mass_only.frame_guides
    recording = read_recording_csv(files.csv)
    assert sorted(recording.channels) == ["x_r", "x_s", "x_t"]
    expected_metadata = {"source", "run", "excitation", "seed", "sweep_start_Hz", "sweep_stop_Hz"}
    assert set(recording.metadata) == expected_metadata
    text = files.csv.read_text().lower() + files.vehicle_toml.read_text().lower()
    assert not any(word in text for word in ("coil", "actuator", "cable", "skyhook", "bearing", "command"))


def test_an_unrecorded_force_acts_between_body_and_wheel_and_changes_the_motion(
    draw: RigDraw, run_a: LabRun
) -> None:
    force = run_a.unrecorded_N
    assert np.std(force) > 0.05  # N: the coil's command, its feedback, cogging and cable
    assert np.std(force) > 0.05 * np.std(run_a.spring_N)
    without = draw.simulate("A", unrecorded=False)
    difference = run_a.recording.true["x_s"] - without.recording.true["x_s"]
    assert np.sqrt(np.mean(difference**2)) > 20 * draw.noise.rms_m
    assert np.array_equal(run_a.recording.true["x_r"], without.recording.true["x_r"])  # same plate
    # the frame's bearings rub too (a force to ground, outside any quarter-car model)
    assert all(np.std(b) > 0.0 for b in run_a.bearing_N)


def test_runs_are_sampled_at_500_Hz(draw: RigDraw, run_a: LabRun, tmp_path: Path) -> None:
    files = write_run(run_a, draw.rig, tmp_path, "rig_A")
    recording = read_recording_csv(files.csv)
    assert recording.sample_time_s == pytest.approx(0.002, rel=1e-9)
    assert recording.time_s.size == round(draw.run("A").duration_s / 0.002) + 1
    assert np.allclose(np.diff(recording.time_s), 0.002, atol=1e-9)


def test_the_lasers_read_with_the_drawn_noise_in_whole_micrometres(draw: RigDraw, run_a: LabRun) -> None:
    noise = draw.noise
    assert noise.lag1_correlation > 0.5  # the fixture's rig has coloured noise
    for name in ("x_s", "x_t", "x_r"):
        measured = run_a.recording.measured[name]
        assert np.allclose(measured / 1e-6, np.round(measured / 1e-6), atol=1e-6)
        error = measured - run_a.recording.true[name]
        assert np.sqrt(np.mean(error**2)) == pytest.approx(noise.rms_m, rel=0.15)
        lag1 = np.corrcoef(error[:-1], error[1:])[0, 1]
        assert lag1 == pytest.approx(noise.lag1_correlation, abs=0.1)
    levels = [draw_rig(seed, run_s=RUN_S).noise for seed in SEEDS]
    assert all(2e-6 <= n.rms_m <= 10e-6 and n.quantum_m == 1e-6 for n in levels)
    coloured = [n.lag1_correlation for n in levels if n.lag1_correlation > 0]
    assert 0.3 * len(levels) < len(coloured) < 0.7 * len(levels)
    assert all(0.3 <= rho <= 0.9 for rho in coloured)


def test_a_rigs_runs_differ(draw: RigDraw) -> None:
    t = np.arange(0.0, RUN_S + 1.0, 0.002)
    plates = {s.name: np.array([s.plate.motion(x)[0] for x in t]) for s in draw.runs}
    commands = {s.name: np.array([s.reference.motion(x)[0] for x in t]) for s in draw.runs}
    assert sorted(plates) == ["A", "B", "C"]
    names = sorted(plates)
    for i, first in enumerate(names):
        assert np.sqrt(np.mean(plates[first] ** 2)) > 2e-4
        assert np.sqrt(np.mean(commands[first] ** 2)) > 0.05
        for second in names[i + 1 :]:
            assert abs(np.corrcoef(plates[first], plates[second])[0, 1]) < 0.5
            assert abs(np.corrcoef(commands[first], commands[second])[0, 1]) < 0.5
    assert len({s.noise_seed for s in draw.runs}) == 3
    assert len({s.description for s in draw.runs}) == 3


def test_the_rigs_are_light_lab_rigs_over_the_documented_ranges() -> None:
    for seed in SEEDS:
        rig = draw_rig(seed, run_s=RUN_S).rig
        assert 1.5 <= rig.sprung_mass_kg <= 4.0 and 0.5 <= rig.unsprung_mass_kg <= 1.5
        assert 500.0 <= rig.spring_N_per_m <= 1500.0 and 1500.0 <= rig.tyre_N_per_m <= 5000.0
        assert rig.damper_friction.breakaway_N >= rig.damper_friction.sliding_N > 0.0
