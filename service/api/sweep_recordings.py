"""A sweep's recording as the input of a job, read where acquisition wrote it (the HDF5 file; the job's
check and the worker read it with daq.formats.recording_file), and as a CSV for download (exported on
request, the server's paths left out). Shared by `POST /sweeps/{id}/jobs`, `GET /sweeps/{id}/recording` and
the inspection-line scheduler. Blocking (files): call it in a thread.

Sweep logic, not HTTP: it raises domain errors (ConflictError, NotFoundError, RecordingFileError ...), which
service.api.errors maps to statuses."""

from __future__ import annotations

from pathlib import Path as FilePath
from pathlib import PurePath

from daq.formats.recording_csv import write_recording_csv
from daq.storage.hdf5_recording import RecordingFileError, export_csv
from estimator.errors import ConflictError, NotFoundError
from service.api.intake import accept_recording
from service.api.settings import ServiceSettings
from service.jobs.diagnose_job import DiagnoseJobOptions
from service.jobs.identify_job import IdentifyJobOptions
from service.jobs.kinds import KINDS
from service.store.jobs import JobRecord, JobStore
from service.store.models import JobKind
from service.store.quota import KeyQuota
from service.store.sweeps import SweepRecord


def recording_path(record: SweepRecord) -> FilePath:
    if not record.finished:
        raise ConflictError(
            f"sweep {record.id} is {record.status.value}; its recording is ready once it has ended"
        )
    path = FilePath(record.recording_path) if record.recording_path else None
    if path is None or not path.is_file():
        raise NotFoundError(f"sweep {record.id} has no recording ({record.reason or 'never recorded'})")
    return path


PATH_METADATA = ("source", "vehicle_file")
"""Metadata lines of an exported CSV that hold a path: written with the file name only, since viewers
download the CSV and the data directory's place on the server is none of theirs."""


def export(h5: FilePath, csv: FilePath) -> None:
    try:
        recording = export_csv(h5, csv)
        recording.metadata = {
            key: (PurePath(value).name if key in PATH_METADATA else value)
            for key, value in recording.metadata.items()
        }
        write_recording_csv(csv, recording)
    except RecordingFileError as exc:  # the same class (gaps too), naming the file, not its place
        raise type(exc)(str(exc).replace(str(h5), h5.name)) from None


def accept_sweep_job(
    settings: ServiceSettings,
    jobs: JobStore,
    record: SweepRecord,
    options: IdentifyJobOptions | DiagnoseJobOptions,
    submitted_by: str | None,
    kind: JobKind = JobKind.IDENTIFY,
    quota: KeyQuota | None = None,
) -> JobRecord:
    """A queued job of `kind` (identification, diagnosis) on the sweep's recording (ConflictError until
    the sweep has ended, a UserError when its recording cannot be read as one). The caller enqueues it
    with the job manager. `quota`: an operator's request keeps its key's limit (service.store.quota)."""
    h5 = recording_path(record)
    assert record.vehicle_file is not None
    return accept_recording(
        settings,
        jobs,
        KINDS[kind.value],
        options,
        h5,
        FilePath(record.vehicle_file),
        submitted_by,
        sweep_id=record.id,
        quota=quota,
    )
