"""Taking in a job: check its input the way the worker will read it, so that a job that cannot run is
refused at submit (InputError naming the field, a 422 by service.api.errors) instead of failing in the
queue; then store it.

Two ways in: `accept_upload` (recording CSV and vehicle file uploaded with the request; they are kept in
the job's folder) and `accept_recording` (a recording already on disk, e.g. a sweep's, with a vehicle
file: the files stay where they are). Both are synchronous (file I/O): call them in a thread. The files
are read and checked in the input checker's process (service.api.input_check), so that a large upload
never holds the service's interpreter.
"""

from __future__ import annotations

import csv
import secrets
import shutil
import tempfile
from pathlib import Path
from typing import Any, BinaryIO

from pydantic import BaseModel

from daq.formats.recording_file import read_recording_file
from daq.formats.vehicle_file import VehicleFile, VehicleFileError, parse_vehicle_file
from daq.storage.hdf5_recording import RecordingFileError
from estimator.errors import one_line
from estimator.recording import Recording
from service.access import Principal
from service.api.settings import ServiceSettings
from service.jobs.context import InputError
from service.jobs.kinds import JobKindSpec
from service.store.jobs import JobFiles, JobRecord, JobStore
from service.store.quota import KeyQuota

RECORDING_FILE = "recording.csv"


def _read_inputs(
    spec: JobKindSpec, recording_path: Path, recording_name: str, vehicle_path: Path, vehicle_name: str
) -> tuple[Recording, Any]:
    """The recording and the kind's companion file (the vehicle file, or a validation's model) as read."""
    try:
        recording = read_recording_file(recording_path)
    except RecordingFileError as exc:  # HDF5 (a sweep's recording): its class kept (gaps: recording_gaps)
        raise type(exc)(str(exc).replace(str(recording_path), recording_name), field="recording") from None
    except (ValueError, csv.Error) as exc:  # RecordingFormatError, bad text encoding, NUL bytes ...
        message = str(exc).replace(str(recording_path), recording_name) or "not a recording CSV"
        if isinstance(exc, UnicodeDecodeError):
            message = f"{recording_name}: not a text file (UTF-8 expected)"
        raise InputError("recording", message) from None
    field = spec.companion.field
    try:
        text = vehicle_path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(field, f"{vehicle_name}: not a text file (UTF-8 expected)") from None
    try:
        return recording, spec.companion.read(text, vehicle_name)
    except ValueError as exc:
        raise InputError(field, one_line(exc)) from None


def parse_vehicle_field(text: str, source: str, field: str) -> VehicleFile:
    """The vehicle file's text as read, or InputError naming `field`: not TOML, wrong keys, or nested so
    deep that the TOML parser runs out of stack."""
    try:
        return parse_vehicle_file(text, source=source)
    except VehicleFileError as exc:
        raise InputError(field, str(exc)) from None


def check_files(
    spec: JobKindSpec,
    options: BaseModel,
    recording_path: Path,
    recording_name: str,
    vehicle_path: Path,
    vehicle_name: str,
) -> None:
    """Read both files and run the kind's checks (InputError naming the field). Runs in the input
    checker's process (service.api.input_check), never in the service's."""
    spec.check(options, *_read_inputs(spec, recording_path, recording_name, vehicle_path, vehicle_name))


def _check_elsewhere(
    spec: JobKindSpec, options: BaseModel, recording: tuple[Path, str], vehicle: tuple[Path, str]
) -> None:
    from service.api.input_check import CHECKER

    CHECKER.check(spec.name, options.model_dump(mode="json"), recording, vehicle)


def _job_folder(settings: ServiceSettings, job_id: int) -> Path:
    """Unique even when a new database starts numbering again over an old data directory."""
    return settings.jobs_dir / f"{job_id:06d}-{secrets.token_hex(4)}"


def accept_upload(
    settings: ServiceSettings,
    store: JobStore,
    spec: JobKindSpec,
    options: BaseModel,
    recording: tuple[str | None, BinaryIO],
    vehicle: tuple[str | None, BinaryIO],
    principal: Principal,
    quota: KeyQuota | None = None,
) -> JobRecord:
    """Check the uploaded files (file name, content), then create the queued job, its folder holding them.
    With `quota`, a key at its limit is refused (QuotaExceededError) before the files are copied, and again
    in the transaction that inserts the job (service.store.quota)."""
    if quota is not None:
        store.check_quota(quota)
    settings.uploads_dir.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix="upload-", dir=settings.uploads_dir))
    try:
        recording_path, vehicle_path = staging / RECORDING_FILE, staging / spec.companion.file_name
        for (_, source), target in ((recording, recording_path), (vehicle, vehicle_path)):
            with target.open("wb") as out:
                shutil.copyfileobj(source, out, 1 << 20)
        names = (recording[0] or "recording", vehicle[0] or spec.companion.field)
        _check_elsewhere(spec, options, (recording_path, names[0]), (vehicle_path, names[1]))

        def place(job_id: int) -> JobFiles:
            folder = _job_folder(settings, job_id)
            settings.jobs_dir.mkdir(parents=True, exist_ok=True)
            staging.rename(folder)
            return JobFiles(folder / RECORDING_FILE, folder / spec.companion.file_name, folder)

        return store.create(
            spec.name,
            options.model_dump(mode="json"),
            place,
            input_source="upload",
            submitted_by=principal.key_id,
            quota=quota,
        )
    finally:
        shutil.rmtree(staging, ignore_errors=True)  # gone already when the job took it


def accept_recording(
    settings: ServiceSettings,
    store: JobStore,
    spec: JobKindSpec,
    options: BaseModel,
    recording_path: Path,
    vehicle_path: Path,
    submitted_by: str | None,
    *,
    sweep_id: int | None = None,
    quota: KeyQuota | None = None,
) -> JobRecord:
    """A job on a recording already on disk (a sweep's): checked alike, the files stay where they are.
    `submitted_by` is the key id of whoever asked (an operator, or the author of a scheduled test); with
    `quota` (an operator's request, not the scheduler's job) its key's limit is kept as in accept_upload."""
    if quota is not None:
        store.check_quota(quota)
    _check_elsewhere(spec, options, (recording_path, recording_path.name), (vehicle_path, vehicle_path.name))

    def place(job_id: int) -> JobFiles:
        folder = _job_folder(settings, job_id)
        folder.mkdir(parents=True)
        return JobFiles(recording_path, vehicle_path, folder)

    return store.create(
        spec.name,
        options.model_dump(mode="json"),
        place,
        input_source="sweep" if sweep_id is not None else "recording",
        sweep_id=sweep_id,
        submitted_by=submitted_by,
        quota=quota,
    )
