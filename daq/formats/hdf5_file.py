"""An HDF5 file told by its content and opened for reading without ever hanging on a damaged one.

Telling: an HDF5 file holds the format signature at its start, or after a user block of 512·2^k bytes
(the superblock's place, as h5py.is_hdf5 looks for it); this module finds it without importing h5py, so
that telling a recording CSV from an HDF5 file costs a few bytes read.

Opening (`open_for_reading`): a file a writer closed is opened as any HDF5 file: the library then checks
that it is not truncated and every metadata checksum, and a damaged file fails at once. Only a file whose
superblock says that a SWMR writer has it open (a sweep still recording, or one whose writer died: see
daq.storage.hdf5_recording, "Crash safety") is opened in SWMR read mode. In that mode HDF5 re-reads a
metadata block whose checksum fails, waiting twice as long each time (its default of 100 attempts adds
up to hours: a truncated copy of such a file hung `shockbench identify`), so the attempts are bounded to
SWMR_READ_ATTEMPTS, and a file shorter than the end its superblock states is refused first.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

if TYPE_CHECKING:
    import h5py

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
SWMR_WRITE_FLAGS = 0x05
"""Superblock (version 3) status flags a SWMR writer sets: open for write (bit 0), SWMR write (bit 2)."""
SWMR_READ_ATTEMPTS = 20
"""Metadata read attempts in SWMR read mode: rides out a block caught mid-write by the writer, and fails
a damaged file in well under a second (HDF5's default, 100, doubles its wait up to an hour per attempt)."""


def _superblock_offset(handle: BinaryIO) -> int | None:
    """Where the signature is (0, 512, 1024, ...), or None."""
    size = os.fstat(handle.fileno()).st_size
    offset = 0
    while offset + len(HDF5_SIGNATURE) <= size:
        handle.seek(offset)
        if handle.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE:
            return offset
        offset = 512 if offset == 0 else 2 * offset
    return None


def has_hdf5_signature(path: Path | str) -> bool:
    """Whether the file holds the HDF5 signature where HDF5 puts it (as h5py.is_hdf5, without h5py)."""
    with open(path, "rb") as handle:
        return _superblock_offset(handle) is not None


@dataclass(frozen=True)
class SwmrState:
    """What the superblock of a file left by a SWMR writer says: its end (bytes, from the file's start)."""

    end_of_file: int


def swmr_state(path: Path | str) -> SwmrState | None:
    """The state of a file whose version-3 superblock carries the SWMR writer's flags, else None.

    Version 3 superblock: signature (8), version, size of offsets O, size of lengths, status flags, then
    base address, extension address, end-of-file address (O bytes each, little-endian)."""
    with open(path, "rb") as handle:
        offset = _superblock_offset(handle)
        if offset is None:
            return None
        handle.seek(offset + len(HDF5_SIGNATURE))
        head = handle.read(4)
        if len(head) < 4 or head[0] != 3 or head[3] & SWMR_WRITE_FLAGS != SWMR_WRITE_FLAGS:
            return None
        size_of_offsets = head[1]
        fields = handle.read(3 * size_of_offsets)
    if size_of_offsets not in (2, 4, 8, 16) or len(fields) < 3 * size_of_offsets:
        return None  # not a valid superblock: the library refuses it
    base = int.from_bytes(fields[:size_of_offsets], "little")
    end = int.from_bytes(fields[2 * size_of_offsets :], "little")
    return SwmrState(end_of_file=base + end)


def _swmr_access() -> h5py.h5p.PropFAID:
    """File access properties with SWMR_READ_ATTEMPTS metadata read attempts (h5py does not expose the
    setting: the library's own function, found through h5py's extension, which links it). Without it
    (a build that hides the symbol) HDF5's default applies."""
    import ctypes

    import h5py

    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    try:
        setter = ctypes.CDLL(h5py.h5p.__file__).H5Pset_metadata_read_attempts
    except (OSError, AttributeError):
        return fapl
    setter.argtypes = [ctypes.c_int64, ctypes.c_uint]
    setter.restype = ctypes.c_int
    setter(fapl.id, SWMR_READ_ATTEMPTS)
    return fapl


def open_for_reading(path: Path | str) -> h5py.File:
    """The HDF5 file at `path`, read-only: plain for a closed file, SWMR read mode for one a SWMR writer
    has (or had, before it died) open. OSError, one line, for a file the library cannot open and for one
    shorter than its superblock says (truncated)."""
    import h5py

    path = Path(path)
    state = swmr_state(path)
    if state is None:
        return h5py.File(path, "r")
    size = path.stat().st_size
    if size < state.end_of_file:
        raise OSError(f"truncated file: {size} bytes, its superblock says {state.end_of_file}")
    flags = h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ
    return h5py.File(h5py.h5f.open(os.fsencode(path), flags, fapl=_swmr_access()))
