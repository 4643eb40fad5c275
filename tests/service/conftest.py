"""Inputs shared by the service's tests."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from live_server import SimulatedInputs, simulated_inputs

from daq.formats.recording_csv import write_recording_csv
from daq.formats.vehicle_file import write_vehicle
from estimator.sweep import SweepSettings
from service.store.database import Database
from simulators.vehicle_sim import (
    SimulationSettings,
    default_axle,
    default_quarter_car,
    simulate,
    with_effects,
)

PLATE_OFFSET_M = 0.0005
"""The plate laser of `plate_offset_files` reads this high (m): a catalog effect for the model doctor."""


@pytest.fixture(scope="session")
def plate_offset_m() -> float:
    return PLATE_OFFSET_M


@pytest.fixture(scope="session")
def plate_offset_files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with rec.csv, a 6 s sweep of the default quarter car whose plate laser reads 0.5 mm high
    (the vehicle file does not say so), its vehicle.toml, and axle.toml (a vehicle file of the wrong kind)."""
    folder = tmp_path_factory.mktemp("plate-offset")
    vehicle = with_effects(default_quarter_car(), sensor_offset_m={"x_r": PLATE_OFFSET_M})
    settings = SimulationSettings(sweep=SweepSettings(duration_s=6.0), seed=3, substeps=2)
    write_recording_csv(folder / "rec.csv", simulate(vehicle, settings).recording)
    write_vehicle(folder / "vehicle.toml", vehicle.known)
    write_vehicle(folder / "axle.toml", default_axle().known)
    return folder


@pytest.fixture(scope="session")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> SimulatedInputs:
    """A 6 s quarter-car recording CSV and its vehicle file with the simulator's truth (read only)."""
    return simulated_inputs(tmp_path_factory.mktemp("inputs"), seconds=6.0, seed=1)


@pytest.fixture
def local(tmp_path: Path) -> Iterator[Database]:
    """The lane's local store: SQLite in its data directory, keeping the outbox."""
    database = Database(f"sqlite:///{tmp_path / 'local.sqlite3'}", outbox=True)
    database.upgrade_schema()
    yield database
    database.dispose()
