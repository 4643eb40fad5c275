"""Recordings on disk: HDF5 files written while acquiring (see hdf5_recording)."""

from daq.storage.hdf5_recording import (
    FLAG_GAP,
    RecordingFileError,
    RecordingGapError,
    RecordingWriter,
    StoredRecording,
    export_csv,
    load_recording,
    read_recording,
)

__all__ = [
    "FLAG_GAP",
    "RecordingFileError",
    "RecordingGapError",
    "RecordingWriter",
    "StoredRecording",
    "export_csv",
    "load_recording",
    "read_recording",
]
