"""Recordings on disk: HDF5 files written while acquiring (RecordingWriter, daq.storage.hdf5_writer), read
back and exported (daq.storage.hdf5_reader), with the file layout both share (daq.storage.hdf5_layout).

Must not import service, simulators or drivers: a recording file is read without a device stack."""

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
