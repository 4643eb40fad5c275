"""A lab rig's runs as its lab would hand them over (simulators.lab_rig): runs A (the chirp) and B (the
random road) written as the rig's own files and read back as the CLI reads them, with the vehicle file that
states the wrong rates or the mass-only one. Shared by the tests of the doctor, identify and DE on that
world, each rig simulated once per test process."""

from __future__ import annotations

from functools import cache
from tempfile import TemporaryDirectory

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from estimator.recording import Recording
from estimator.vehicle import VehicleParameters
from simulators.lab_rig.draws import draw_rig
from simulators.lab_rig.world import write_run


@cache
def lab_rig_runs(seed: int, mass_only: bool = False) -> tuple[Recording, Recording, VehicleParameters]:
    """Runs A and B of rig `seed` and its vehicle file: the stated (wrong) rates, or the masses alone."""
    draw = draw_rig(seed)
    with TemporaryDirectory() as folder:
        files = [write_run(draw.simulate(run), draw.rig, folder, f"rig_{seed}_{run}") for run in "AB"]
        a, b = (read_recording_csv(f.csv) for f in files)
        return a, b, read_vehicle(files[0].mass_only_toml if mass_only else files[0].vehicle_toml)
