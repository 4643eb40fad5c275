"""A sweep's recording as the input of a job: the HDF5 recording exported once to a recording CSV beside
it (a finished recording never changes), then taken in like any recording on disk. Shared by
`POST /sweeps/{id}/jobs` and the inspection-line scheduler. Blocking (files): call it in a thread.

Sweep logic, not HTTP: it raises domain errors (ConflictError, NotFoundError, RecordingFileError ...), which
service.api.errors maps to statuses."""

from __future__ import annotations

import os
import secrets
from pathlib import Path as FilePath
from pathlib import PurePath

from daq.formats.recording_csv import write_recording_csv
from daq.storage.hdf5_recording import RecordingFileError, export_csv
from estimator.errors import ConflictError, NotFoundError
from service.api.intake import accept_recording
from service.api.settings import ServiceSettings
from service.jobs.identify_job import IdentifyJobOptions
from service.jobs.kinds import KINDS
from service.store.jobs import JobRecord, JobStore
from service.store.models import JobKind
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
EXPORT_VERSION = 2
"""Part of the CSV's name: a CSV exported before paths were stripped is exported again, not served."""


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


def sweep_csv(record: SweepRecord) -> FilePath:
    """The recording as CSV beside the HDF5 file (exported once; a finished recording never changes)."""
    h5 = recording_path(record)
    csv = h5.with_suffix(f".v{EXPORT_VERSION}.csv")
    if not csv.is_file():
        partial = csv.with_name(f".{csv.name}.{secrets.token_hex(4)}.part")
        try:
            export(h5, partial)
            os.replace(partial, csv)
        finally:
            partial.unlink(missing_ok=True)
    return csv


def accept_sweep_job(
    settings: ServiceSettings,
    jobs: JobStore,
    record: SweepRecord,
    options: IdentifyJobOptions,
    submitted_by: str | None,
) -> JobRecord:
    """A queued identification job on the sweep's recording (ConflictError until the sweep has ended, a
    UserError when its recording cannot be read as one). The caller enqueues it with the job manager."""
    csv = sweep_csv(record)
    assert record.vehicle_file is not None
    return accept_recording(
        settings,
        jobs,
        KINDS[JobKind.IDENTIFY.value],
        options,
        csv,
        FilePath(record.vehicle_file),
        submitted_by,
        sweep_id=record.id,
    )
