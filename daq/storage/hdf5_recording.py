"""A recording on disk, one HDF5 file per recording: the public names of daq.storage's HDF5 modules in one
place, under the import path the callers have always used.

- daq.storage.hdf5_layout: the file's layout and crash safety (why HDF5, SWMR), its constants and errors;
- daq.storage.hdf5_writer: RecordingWriter, appending while the bench acquires;
- daq.storage.hdf5_reader: load_recording, read_recording and export_csv.
"""

from __future__ import annotations

from daq.storage.hdf5_layout import (
    FLAG_GAP,
    FORMAT_NAME,
    FORMAT_VERSION,
    GRID_TOLERANCE,
    NOT_CLOSED_REASON,
    REASON_BYTES,
    MetadataValue,
    RecordingFileError,
    RecordingGapError,
)
from daq.storage.hdf5_reader import (
    CSV_SKIPPED_METADATA,
    StoredRecording,
    export_csv,
    load_recording,
    read_recording,
)
from daq.storage.hdf5_writer import RecordingWriter

__all__ = [
    "CSV_SKIPPED_METADATA",
    "FLAG_GAP",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "GRID_TOLERANCE",
    "NOT_CLOSED_REASON",
    "REASON_BYTES",
    "MetadataValue",
    "RecordingFileError",
    "RecordingGapError",
    "RecordingWriter",
    "StoredRecording",
    "export_csv",
    "load_recording",
    "read_recording",
]
