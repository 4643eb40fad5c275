"""What a Dask worker runs: a batch of recordings, each with the analyses asked for it. The client ships
each recording's bytes and its vehicle file's text with the task (a `Payload`: from the database's
recordings or read from the source folder), so the workers need no shared folder and no database
connection (issue 33). A worker writes the bytes to a file in its own temporary folder, reads it as
`shockbench identify`/`diagnose` do (service.analysis), and hands back each result's JSON or the one-line
reason it failed, naming the recording as the client knows it. It never raises for a bad recording: one bad
file fails alone.

Batching (several recordings per task) keeps Dask's per-task cost (about 5-10 ms of scheduling and
serialisation) off each recording; `WorkerSetup` gives every worker one BLAS thread (two workers of two
threads each on two cores made small matrix products many times slower) and loads the estimator and its
compiled kernel once, when the worker joins, not in the first task.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import time
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path, PurePath
from typing import Any

from estimator.errors import UserError, one_line
from service.reanalyse.sources import Item

BLAS_THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""The environment of a worker process the local cluster starts: one BLAS thread from the first import."""


DOCTOR_PROCESSES = 1
"""The model doctor's processes in a task (DiagnoseOptions.workers; the diagnosis does not depend on it):
the cluster already runs a worker per core, so a doctor forking two more would share the cores four ways,
and forking a worker, which runs Dask's threads, would risk a child waiting on a lock one of them held."""


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


@dataclass(frozen=True)
class Payload:
    """A recording as shipped to a worker: its file's bytes (zlib-compressed when `compressed`), the file
    name to read it under (its suffix tells nothing: the content does), its vehicle file's text (None: the
    HDF5 recording's own) and the vehicle file's name for messages."""

    file_name: str
    data: bytes
    compressed: bool
    vehicle_text: str | None
    vehicle_source: str | None


@dataclass(frozen=True)
class Work:
    """One recording of a batch and the analyses to run on it."""

    payload: Payload
    tasks: tuple[Task, ...]


class NoVehicleError(UserError, ValueError):
    """A recording with neither a vehicle file nor a vehicle text inside."""


def payload_of(item: Item) -> Payload:
    """The payload of a recording in a folder: its file and vehicle file read here (OSError, UserError:
    one line naming the file)."""
    from daq.formats.vehicle_file import load_vehicle_file

    if item.problem is not None:
        raise NoVehicleError(item.problem)
    vehicle_text = load_vehicle_file(item.vehicle).text if item.vehicle is not None else None
    data = item.recording.read_bytes()
    return Payload(
        item.recording.name, data, False, vehicle_text, str(item.vehicle) if item.vehicle else None
    )


_FOLDER: list[Path] = []
SCRATCH_PREFIX = "shockbench-reanalyse-"


def _scratch() -> Path:
    """This process's folder for the recordings it reads, named by its process id: removed when the process
    ends normally, and on POSIX by the next worker to start when it was killed (remove_orphaned_scratch)."""
    if not _FOLDER:
        if os.name == "posix":  # (Windows's os.kill(pid, 0) would send the process Ctrl+C)
            remove_orphaned_scratch(Path(tempfile.gettempdir()))
        folder = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-"))
        atexit.register(shutil.rmtree, folder, True)
        _FOLDER.append(folder)
    return _FOLDER[0]


def remove_orphaned_scratch(root: Path) -> list[Path]:
    """Remove the scratch folders under `root` whose process no longer runs (a worker killed before its
    atexit); a folder of a running process, or of another user's, is kept. Returns those removed."""
    removed = []
    for folder in root.glob(f"{SCRATCH_PREFIX}*-*"):
        pid = folder.name[len(SCRATCH_PREFIX) :].split("-", 1)[0]
        if not pid.isdigit() or not folder.is_dir():
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
        except PermissionError:
            continue  # another user's process runs under that id
    return removed


def analyse(task: Task, path: Path, payload: Payload) -> dict[str, Any]:
    """The JSON `shockbench identify --json` (or `diagnose --json`) prints for the recording at `path`,
    with NaN and ±inf as null. Raises on bad input."""
    from daq.formats.recording_file import read_recording_file
    from daq.formats.vehicle_file import parse_vehicle
    from estimator.vehicle import TyreModel
    from service.analysis import diagnose_recording, identify_recording
    from service.jobs.context import finite_json

    recording = read_recording_file(path)
    text = payload.vehicle_text
    source = payload.vehicle_source or f"{path} (its vehicle text)"
    if text is None:
        text = recording.metadata.get("vehicle_text")
        if not text:
            raise NoVehicleError(f"{path}: no vehicle file, and the recording carries no vehicle text")
    vehicle = parse_vehicle(text, source)
    tyre, points = TyreModel(task.options.tyre), task.options.points
    if task.analysis is Analysis.IDENTIFY:
        from estimator.identify import IdentifyOptions

        result = identify_recording(recording, vehicle, IdentifyOptions(tyre=tyre, points=points)).to_json()
    else:
        from estimator.doctor.diagnose import DiagnoseOptions

        options = DiagnoseOptions(tyre=tyre, points=points, workers=DOCTOR_PROCESSES)
        result = diagnose_recording(recording, vehicle, options).to_json()
    return finite_json(result)


def _reason(exc: BaseException, path: Path, label: str) -> str:
    """The exception in one line, the worker's scratch file named as the client knows the recording."""
    text = one_line(exc).replace(str(path), label)
    return text if isinstance(exc, UserError | OSError) else f"internal error: {type(exc).__name__}: {text}"


def _run_work(work: Work) -> list[Outcome]:
    start = time.perf_counter()
    label = str(work.tasks[0].item.recording)
    path = _scratch() / PurePath(work.payload.file_name).name
    try:
        data = zlib.decompress(work.payload.data) if work.payload.compressed else work.payload.data
        path.write_bytes(data)
    except (OSError, zlib.error) as exc:
        reason = _reason(exc, path, label)
        return [Outcome(task, None, reason, time.perf_counter() - start) for task in work.tasks]
    outcomes = []
    try:
        for task in work.tasks:
            begun = time.perf_counter()
            try:
                result = analyse(task, path, work.payload)
            except Exception as exc:  # a bug on this recording must not stop the archive
                outcomes.append(Outcome(task, None, _reason(exc, path, label), time.perf_counter() - begun))
                continue
            outcomes.append(Outcome(task, result, None, time.perf_counter() - begun))
    finally:
        path.unlink(missing_ok=True)
    return outcomes


def run_batch(batch: Sequence[Work]) -> list[Outcome]:
    """Runs on a Dask worker: every analysis of every recording of the batch, in order."""
    return [outcome for work in batch for outcome in _run_work(work)]


def run_task(task: Task) -> Outcome:
    """One analysis of a recording in a folder, in this process (the in-process reference the benchmark
    compares a worker with): the result, or the one-line reason it failed."""
    start = time.perf_counter()
    try:
        payload = payload_of(task.item)
    except (UserError, OSError) as exc:
        return Outcome(task, None, one_line(exc), time.perf_counter() - start)
    (outcome,) = run_batch([Work(payload, (task,))])
    return outcome


def warm_up() -> None:
    """Load what an analysis needs (numpy, scipy, the estimator, its compiled kernel) and keep BLAS to one
    thread in this process: what a worker does once when it joins (run.WorkerSetup)."""
    os.environ.update(BLAS_THREADS)  # for any process it starts
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # without it, the environment above (set before numpy loads) is what holds
        pass
    else:
        threadpool_limits(1)
    import estimator.identify
    import estimator.simulation_kernel  # noqa: F401
    import service.analysis  # noqa: F401
