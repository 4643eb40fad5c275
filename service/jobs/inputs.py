"""The file a job kind takes beside its recording: the vehicle file (identify, diagnose) or an identified
model (validate). One description per kind of file: its form field, the name it is kept under in the job's
folder, its media type, and how it is read (the same reader at submit and in the worker).

A reader takes the file's text and a name to quote, and raises ValueError (one line, naming the problem)."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from daq.formats.vehicle_file import parse_vehicle_file
from estimator.errors import InvalidValueError
from estimator.vehicle import VehicleParameters


@dataclass(frozen=True)
class CompanionFile:
    field: str
    """Form field of the upload, and the `field` a 422 about it names."""
    file_name: str
    """Name in the job's folder."""
    media_type: str
    description: str
    read: Callable[[str, str], Any]
    """(text, name to quote) -> what the kind's check and runner take."""
    vehicle_of: Callable[[Any], VehicleParameters]
    """The vehicle the job runs on (JobContext.vehicle)."""


def _read_vehicle(text: str, source: str) -> VehicleParameters:
    return parse_vehicle_file(text, source=source).parameters


def _read_model(text: str, source: str) -> Any:
    """An identified model from the JSON identify --json (or diagnose --json) prints."""
    from estimator.model_io import model_from_json

    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InvalidValueError(f"{source}: not JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise InvalidValueError(f"{source}: not valid JSON (nested too deeply)") from None
    if not isinstance(data, dict):
        raise InvalidValueError(
            f"{source}: expected a JSON object (the output of identify or diagnose --json)"
        )
    return model_from_json(data)


VEHICLE_FILE = CompanionFile(
    field="vehicle",
    file_name="vehicle.toml",
    media_type="application/toml",
    description="vehicle file, TOML (UTF-8): one [vehicle] table; its model must match the recording",
    read=_read_vehicle,
    vehicle_of=lambda vehicle: vehicle,
)

MODEL_FILE = CompanionFile(
    field="model",
    file_name="model.json",
    media_type="application/json",
    description="identified model, JSON (UTF-8): the output of `shockbench identify --json`, or of "
    "`shockbench diagnose --json` (its `model`, effects included); an axle model states track_m; its kind "
    "must match the recording",
    read=_read_model,
    vehicle_of=lambda model: model.vehicle,
)
