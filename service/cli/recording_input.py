"""The recording and vehicle a command line names, read as the worker and `reanalyse` read them
(daq.formats.recording_file: an HDF5 sweep or a recording CSV, told apart by content).

Without --vehicle, the vehicle is the one an HDF5 sweep carries (the vehicle file's text as the sweep ran
with it), said on stderr; a recording CSV carries none, so it needs --vehicle (CliError, exit 2)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

from service.cli.errors import CliError

if TYPE_CHECKING:
    from daq.formats.recording_file import RecordingFile
    from estimator.recording import Recording
    from estimator.vehicle import VehicleParameters

VEHICLE_HELP = (
    "vehicle file (TOML); without it, the vehicle an HDF5 sweep carries (a recording CSV needs --vehicle)"
)
RECORDING_HELP = "recording: an HDF5 sweep (shockbench sweep) or a recording CSV, told apart by content"


def load_recording(command: str, recording_path: str) -> RecordingFile:
    """The recording at `recording_path` (UserError, one line naming the file). An HDF5 recording with
    gaps is refused (RecordingGapError) with the way out the command line has: `export --allow-gaps`."""
    from daq.formats.recording_file import load_recording_file

    advice = (
        f"{command} needs gap-free data: `shockbench export {recording_path} --out REC.csv --allow-gaps` "
        "writes its longest gap-free stretch"
    )
    return load_recording_file(recording_path, gap_advice=advice)


def read_recording_and_vehicle(
    command: str, recording_path: str, vehicle_path: str | None
) -> tuple[Recording, VehicleParameters]:
    """The recording at `recording_path` and the vehicle: the file `vehicle_path`, else the vehicle the
    HDF5 sweep carries (one line on stderr says so). UserError, one line naming the file, on bad input."""
    from daq.formats.recording_file import RecordingFormat, recording_format
    from daq.formats.vehicle_file import parse_vehicle, read_vehicle

    path = Path(recording_path)
    if vehicle_path is None and recording_format(path) is RecordingFormat.CSV:
        raise CliError(f"{path}: a recording CSV carries no vehicle; give --vehicle V.toml", field="vehicle")
    loaded = load_recording(command, recording_path)
    if vehicle_path is not None:
        return loaded.recording, read_vehicle(vehicle_path)
    if loaded.vehicle_text is None:
        raise CliError(
            f"{path}: the HDF5 recording carries no vehicle file; give --vehicle V.toml", field="vehicle"
        )
    vehicle = parse_vehicle(loaded.vehicle_text, f"{path} (its vehicle text)")
    named = loaded.recording.metadata.get("vehicle_file") or "not named"
    recorded_from = "".join(c if c.isprintable() else "?" for c in named)  # a name, never terminal codes
    print(
        f"shockbench {command}: vehicle: taken from the sweep file {path} (the vehicle file it was "
        f"recorded with, {recorded_from}: {vehicle.model.value}, {vehicle.mass_kg:g} kg)",
        file=sys.stderr,
    )
    return loaded.recording, vehicle
