"""Draws of the independent world as the doctor's tests read them: drawn, simulated, written as the
recording CSV and vehicle TOML a user would hand over (ϑ stated at the vehicle file's reference sample time),
and read back by the project's own readers."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from estimator.recording import Recording
from estimator.vehicle import REFERENCE_SAMPLE_TIME_S, VehicleParameters
from simulators.independent.cases import Case, draw_case, simulate_case
from simulators.independent.files import write_recording
from simulators.independent.world import WorldRecording


def recorded(
    label: str, seed: int, folder: Path, sweep_s: float
) -> tuple[Case, WorldRecording, Recording, VehicleParameters]:
    """The case `label`/`seed` with a sweep of sweep_s, its world, and the recording and vehicle read back
    from the files written into `folder` (named after the case)."""
    case = draw_case(label, seed, sweep_s=sweep_s)
    case = replace(case, settings=replace(case.settings, theta_reference_s=REFERENCE_SAMPLE_TIME_S))
    world = simulate_case(case)
    csv_path, toml_path = folder / f"{label}_{seed}.csv", folder / f"{label}_{seed}.toml"
    write_recording(world, csv_path, toml_path)
    return case, world, read_recording_csv(csv_path), read_vehicle(toml_path)
