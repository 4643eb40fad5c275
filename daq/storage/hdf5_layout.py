"""A recording on disk: one HDF5 file per recording, appended while the bench acquires.

Why HDF5 (h5py):

* chunked, resizable datasets take appends block by block while acquiring, without rewriting the file;
* the metadata (bench, vehicle file and its text, sweep, devices and firmware, rates, operator, start time,
  software version, complete/incomplete and why) travel inside the file as attributes on the root group;
* a partially written file stays readable: after a crash or power loss the samples up to the last flush
  are there (see "Crash safety");
* one self-describing file per recording, readable by any HDF5 tool (h5dump, HDFView, MATLAB, pandas).

Layout (all on the common sample grid, 1 ms at the bench)::

    /time                float64 [n]  s, t0 + i * sample_time_s
    /flags               uint8   [n]  bit 0 (FLAG_GAP): no measured sample within one period in at least
                                      one channel; that channel's value is NaN, never filled. Bits 1-7 are
                                      passed through from the acquisition (reserved).
    /channels/<name>     float64 [n]  m, displacement, upward positive, from the static position
    /flushed_samples     int64   [1]  rows known to be on disk (updated at every flush)
    root attributes                   metadata, see RecordingWriter

Crash safety: the writer uses HDF5's SWMR mode (single writer, multiple readers; libver="latest"): the library
orders its metadata writes so that the file on disk is valid after every flush, and a reader in SWMR mode
(daq.formats.hdf5_file) sees every flushed row while the writer is appending, or after it died. (A plain HDF5
file in the latest format is flagged "open for write" in its superblock and cannot be opened after a crash
without ``h5clear``; in the old format its on-disk metadata may be inconsistent between flushes. Checked with
h5py 3.16 / HDF5 2.0: a killed writer's file opens in SWMR mode with exactly the flushed rows.)

The writer flushes whenever a second (``flush_interval_s``) of recorded time has accumulated since the last
flush, so after every ``append`` less than one second of samples is not yet on disk: a crash loses at most
the last second. Readers trust only the rows counted in /flushed_samples, so rows whose extent reached the
disk before their data did are never read as values.

SWMR forbids creating attributes while appending, so every attribute ``close`` writes (status, reason,
counts, end time, achieved rates of the sources declared at construction) is created with a fixed size
before SWMR starts and modified in place at the end. A file whose status is still "recording" was never
closed: it is read as incomplete, reason "not closed by the writer (crash or power loss)".

This module holds what the writer (daq.storage.hdf5_writer) and the reader (daq.storage.hdf5_reader)
share: the layout's constants, the attribute types, the errors and the gap runs.
"""

from __future__ import annotations

import h5py
import numpy as np

from estimator.errors import UserError

FLAG_GAP = 0x01
"""flags bit 0: no measured sample within one period; the NaN value(s) of that row are not filled."""

FORMAT_NAME = "shockbench-recording"
FORMAT_VERSION = 1
GRID_TOLERANCE = 1e-3
"""A timestamp may differ from its grid point by this fraction of the sample time."""
REASON_BYTES = 256
"""The reason of an incomplete recording is stored in this many UTF-8 bytes (longer ones are cut)."""
NOT_CLOSED_REASON = "not closed by the writer (crash or power loss); samples up to the last flush"

MetadataValue = str | int | float
STATUS_DTYPE = h5py.string_dtype("utf-8", 16)
REASON_DTYPE = h5py.string_dtype("utf-8", REASON_BYTES)
TIME_DTYPE = h5py.string_dtype("utf-8", 40)
RESERVED_ATTRIBUTES = frozenset(
    {
        "format",
        "format_version",
        "channels",
        "sample_time_s",
        "status",
        "reason",
        "samples",
        "gaps",
        "gap_samples",
        "first_gap_s",
        "end_time",
        "vehicle_file",
        "vehicle_text",
    }
)
"""Root attributes the writer sets itself: a caller's metadata may not name them."""
RATE_PREFIX = "rate_Hz."
"""Attribute "rate_Hz.<source>": a source's nominal rate, then its achieved rate once closed."""


class RecordingFileError(UserError, ValueError):
    """The file is not a readable shockbench HDF5 recording; the message is one line naming the file."""


class RecordingGapError(RecordingFileError):
    """The recording has gaps (NaN samples) where the caller needs gap-free data."""


def gap_runs(gap: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges of consecutive True values."""
    edges = np.diff(np.concatenate(([0], gap.astype(np.int8), [0])))
    return list(zip(np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist(), strict=True))
