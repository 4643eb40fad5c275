"""What a Dask worker runs for one recording and one analysis: read the recording (CSV or HDF5) and its
vehicle file, run the identification or the model doctor as `shockbench identify`/`diagnose` do
(service.analysis), and hand back the result's JSON or the one-line reason it failed. It never raises for
a bad recording: one bad file fails alone.

The worker reads the files by path: with a scheduler elsewhere, the workers must see SOURCE (and a
database's recording paths) at the same paths as the client (a shared file system); the client writes the
results.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Any

from estimator.errors import UserError, one_line
from service.reanalyse.sources import Item

if TYPE_CHECKING:
    from estimator.recording import Recording
    from estimator.vehicle import VehicleParameters


class Analysis(StrEnum):
    IDENTIFY = "identify"
    DIAGNOSE = "diagnose"


@dataclass(frozen=True)
class AnalysisOptions:
    """The options both commands share: tyre model of the (starting) model and damper curve points (None:
    each command's default). A stored result made with other options is run again."""

    tyre: str = "maxwell"
    points: int | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"tyre": self.tyre, "points": self.points}


@dataclass(frozen=True)
class Task:
    item: Item
    analysis: Analysis
    options: AnalysisOptions


@dataclass(frozen=True)
class Outcome:
    """result: the command's JSON (finite numbers only) when ok; reason: one line when not; seconds: wall
    time on the worker, reading included."""

    task: Task
    result: dict[str, Any] | None
    reason: str | None
    seconds: float

    @property
    def ok(self) -> bool:
        return self.reason is None


class NoVehicleError(UserError, ValueError):
    """A recording with neither a vehicle file nor a vehicle text inside."""


def read_inputs(item: Item) -> tuple[Recording, VehicleParameters]:
    """The recording and its vehicle parameters (UserError/OSError, one line, on bad input)."""
    from daq.formats.recording_file import read_recording_file
    from daq.formats.vehicle_file import parse_vehicle, read_vehicle

    recording = read_recording_file(item.recording)
    if item.vehicle is not None:
        return recording, read_vehicle(item.vehicle)
    text = recording.metadata.get("vehicle_text")
    if not text:
        raise NoVehicleError(f"{item.recording}: no vehicle file, and the recording carries no vehicle text")
    return recording, parse_vehicle(text, f"{item.recording} (its vehicle text)")


def analyse(task: Task) -> dict[str, Any]:
    """The JSON `shockbench identify --json` (or `diagnose --json`) prints for this recording, with NaN
    and ±inf as null. Raises on bad input."""
    from estimator.vehicle import TyreModel
    from service.analysis import diagnose_recording, identify_recording
    from service.jobs.context import finite_json

    if task.item.problem is not None:
        raise NoVehicleError(task.item.problem)
    recording, vehicle = read_inputs(task.item)
    tyre, points = TyreModel(task.options.tyre), task.options.points
    if task.analysis is Analysis.IDENTIFY:
        from estimator.identify import IdentifyOptions

        result = identify_recording(recording, vehicle, IdentifyOptions(tyre=tyre, points=points)).to_json()
    else:
        from estimator.doctor.diagnose import DiagnoseOptions

        result = diagnose_recording(recording, vehicle, DiagnoseOptions(tyre=tyre, points=points)).to_json()
    return finite_json(result)


def run_task(task: Task) -> Outcome:
    """Runs on a Dask worker: the analysis, or the one-line reason it failed (bad input as the command
    says it; anything else named by its exception type, as an internal error)."""
    start = time.perf_counter()
    try:
        result = analyse(task)
    except (UserError, OSError) as exc:
        return Outcome(task, None, one_line(exc), time.perf_counter() - start)
    except Exception as exc:  # a bug on this recording must not stop the archive
        reason = f"internal error: {type(exc).__name__}: {one_line(exc)}"
        return Outcome(task, None, reason, time.perf_counter() - start)
    return Outcome(task, result, None, time.perf_counter() - start)
