"""The physics simulator: accurate integration, statics, sensors, and the coupled bench."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from estimator.sweep import SweepSettings
from simulators.vehicle_on_plate import VehicleOnPlate
from simulators.vehicle_sim import (
    SensorModel,
    SimulationSettings,
    default_axle,
    default_quarter_car,
    simulate,
)

SHORT = SweepSettings(duration_s=4.0)


def test_halving_the_step_changes_the_response_by_less_than_a_micrometre() -> None:
    vehicle = default_quarter_car()
    noiseless = SensorModel(noise_m=0.0, resolution_m=0.0)
    coarse = simulate(vehicle, SimulationSettings(sweep=SHORT, sensor=noiseless, substeps=2))
    fine = simulate(vehicle, SimulationSettings(sweep=SHORT, sensor=noiseless, substeps=4))
    for name in ("x_s", "x_t"):
        assert np.max(np.abs(coarse.recording.channels[name] - fine.recording.channels[name])) < 1e-6


def test_sensor_noise_and_resolution_are_as_configured() -> None:
    vehicle = default_quarter_car()
    clean = simulate(vehicle, SimulationSettings(sweep=SHORT, sensor=SensorModel(0.0, 0.0)))
    noisy = simulate(vehicle, SimulationSettings(sweep=SHORT, sensor=SensorModel(5e-6, 1e-6), seed=3))
    residual = noisy.recording.channels["x_s"] - clean.recording.channels["x_s"]
    assert 4.5e-6 < np.std(residual) < 5.5e-6
    steps = noisy.recording.channels["x_s"] / 1e-6
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)


def test_at_rest_nothing_moves_and_the_plate_follows_the_sweep() -> None:
    vehicle = default_quarter_car()
    quiet = simulate(
        vehicle, SimulationSettings(sweep=replace(SHORT, amplitude_m=0.0), sensor=SensorModel(0, 0))
    )
    for x in quiet.recording.channels.values():
        assert np.max(np.abs(x)) < 1e-12  # only round-off: no excitation, no motion
    moving = simulate(vehicle, SimulationSettings(sweep=SHORT, sensor=SensorModel(0, 0)))
    assert np.max(np.abs(moving.recording.channels["x_r"])) <= 0.004 + 1e-12
    assert np.max(np.abs(moving.recording.channels["x_r"])) > 0.0039


def test_axle_without_bar_and_equal_dampers_does_not_roll_when_plates_move_together() -> None:
    vehicle = default_axle(anti_roll_bar_N_per_m=0.0)
    vehicle = replace(vehicle, dampers=(vehicle.dampers[0], vehicle.dampers[0]))
    result = simulate(
        vehicle, SimulationSettings(sweep=SHORT, sensor=SensorModel(0, 0), right_plate_phase_deg=0)
    )
    ch = result.recording.channels
    assert np.max(np.abs(ch["x_s_l"] - ch["x_s_r"])) < 1e-9
    assert np.max(np.abs(ch["x_s_l"])) > 1e-4


def test_vehicle_bench_in_simulated_time_agrees_with_the_batch_simulator() -> None:
    """The bench the simulated devices read gives the same corner motion as the batch simulation."""
    vehicle = default_quarter_car()
    bench = VehicleOnPlate(vehicle, step_s=0.00025)
    bench.start_sweep(SHORT)
    readings = []
    for _ in range(2000):
        bench.clock.advance(0.001)
        readings.append(bench.position_m("x_s"))
    batch = simulate(vehicle, SimulationSettings(sweep=SHORT, sensor=SensorModel(0, 0)))
    reference = batch.recording.channels["x_s"][1:2001]
    assert np.max(np.abs(np.array(readings) - reference)) < 2e-6
