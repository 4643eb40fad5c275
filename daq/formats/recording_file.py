"""A recording on disk as the estimator sees it, whichever its format: HDF5 as acquisition writes it
(daq.storage.hdf5_recording, a sweep's recording read where the sweep wrote it) or the recording CSV
(daq.formats.recording_csv, an upload or an export). One function, so that a job's submit check and the
worker read a recording alike.

Errors: RecordingFormatError (CSV) or RecordingFileError/RecordingGapError (HDF5), one line naming the
file. An HDF5 recording with gaps is refused (RecordingGapError): nothing is filled in silently.
"""

from __future__ import annotations

from pathlib import Path

from daq.formats.recording_csv import read_recording_csv
from estimator.recording import Recording

HDF5_SUFFIXES = (".h5", ".hdf5")


def is_hdf5(path: Path | str) -> bool:
    return Path(path).suffix.lower() in HDF5_SUFFIXES


def read_recording_file(path: Path | str) -> Recording:
    """The recording at `path`: HDF5 by its suffix (.h5, .hdf5), else a recording CSV."""
    if is_hdf5(path):
        from daq.storage.hdf5_recording import read_recording

        recording, _metadata, _flags = read_recording(path)
        return recording
    return read_recording_csv(path)
