"""A recording on disk as the estimator sees it, whichever its format: HDF5 as acquisition writes it
(daq.storage.hdf5_recording, a sweep's recording read where the sweep wrote it) or the recording CSV
(daq.formats.recording_csv, an upload or an export). One reader, so that the command line (`identify`,
`diagnose`, `validate`, `export`), a job's submit check, the worker and `reanalyse` read a recording alike.

The format is told by the content, not by the name: a file holding the HDF5 signature (at its start, or
after a user block: daq.formats.hdf5_file) is read as an HDF5 recording, anything else as a recording CSV.
So a sweep renamed .csv, or a CSV saved as .h5, is read for what it is (friendlier than refusing it); a
file named .h5 that is neither says both ("REC.h5: not an HDF5 file (no HDF5 signature), nor a recording
CSV: line 1: ...").

Errors, all a UserError with one line naming the file: NotARecordingError (missing, a folder, empty),
RecordingFormatError (CSV), RecordingFileError (HDF5). An HDF5 recording with gaps is refused
(RecordingGapError) unless the caller asks for its longest gap-free stretch: nothing is filled in silently.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

from daq.formats.hdf5_file import has_hdf5_signature
from daq.formats.recording_csv import RecordingFormatError, read_recording_csv, write_recording_csv
from estimator.errors import InvalidValueError, UserError, one_line

if TYPE_CHECKING:
    from estimator.recording import Recording

HDF5_SUFFIXES = (".h5", ".hdf5")


class NotARecordingError(UserError, ValueError):
    """The path holds no recording at all (missing, a folder, an empty file); one line naming it."""


class RecordingFormat(StrEnum):
    """What a recording file's content shows it to be."""

    HDF5 = "HDF5"
    CSV = "CSV"


def named_hdf5(path: Path | str) -> bool:
    """Whether the name says HDF5 (.h5, .hdf5); the content decides how the file is read."""
    return Path(path).suffix.lower() in HDF5_SUFFIXES


def recording_format(path: Path | str) -> RecordingFormat:
    """The format of the file at `path`, by its content (NotARecordingError: missing, a folder, empty)."""
    path = Path(path)
    if path.is_dir():
        raise NotARecordingError(f"{path}: is a folder, not a recording file")
    if not path.is_file():
        raise NotARecordingError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise NotARecordingError(f"{path}: empty file (no recording in it)")
    return RecordingFormat.HDF5 if has_hdf5_signature(path) else RecordingFormat.CSV


@dataclass(frozen=True)
class RecordingFile:
    """A recording as read from `path`, and the format its content showed."""

    path: Path
    format: RecordingFormat
    recording: Recording

    @property
    def vehicle_text(self) -> str | None:
        """The vehicle file's text an HDF5 sweep carries (as the sweep was run with it), unparsed: the
        caller reads it at its edge (tests/test_checked_once.py). None when it carries none; a recording
        CSV never does."""
        text = self.recording.metadata.get("vehicle_text")
        return text if self.format is RecordingFormat.HDF5 and text else None


@contextmanager
def _hdf5_errors(path: Path) -> Iterator[None]:
    """The Recording's own checks (e.g. time not uniform) as a RecordingFileError naming the file."""
    from daq.storage.hdf5_recording import RecordingFileError

    try:
        yield
    except InvalidValueError as exc:
        raise RecordingFileError(f"{path}: {one_line(exc)}") from None


def _csv_for_hdf5_name(path: Path, exc: RecordingFormatError) -> RecordingFormatError:
    """A file named .h5 that is neither format: both said in one line."""
    problem = str(exc).removeprefix(str(path)).removeprefix(":")
    where, _, rest = problem.partition(": ")
    problem = f"line {where}: {rest}" if where.isdigit() else problem.strip()
    return RecordingFormatError(
        f"{path}: not an HDF5 file (no HDF5 signature), nor a recording CSV: {problem}"
    )


def load_recording_file(
    path: Path | str, *, allow_gaps: bool = False, gap_advice: str | None = None
) -> RecordingFile:
    """The recording at `path`, HDF5 or CSV by its content. An HDF5 recording with gaps raises
    RecordingGapError (counting them, naming the first), its advice `gap_advice` when given (the way out
    the caller offers); with allow_gaps it gives its longest gap-free stretch instead (metadata
    gap_free_stretch says which)."""
    path = Path(path)
    found = recording_format(path)
    if found is RecordingFormat.HDF5:
        from daq.storage.hdf5_recording import RecordingGapError, read_recording

        try:
            with _hdf5_errors(path):
                recording, _metadata, _flags = read_recording(path, allow_gaps=allow_gaps)
        except RecordingGapError as exc:
            if gap_advice is None:
                raise
            gaps = one_line(exc).partition("; use allow_gaps")[0]  # the file and its gaps, advice apart
            raise RecordingGapError(f"{gaps}; {gap_advice}") from None
        return RecordingFile(path, found, recording)
    try:
        return RecordingFile(path, found, read_recording_csv(path))
    except RecordingFormatError as exc:
        if named_hdf5(path):
            raise _csv_for_hdf5_name(path, exc) from None
        raise


def read_recording_file(path: Path | str) -> Recording:
    """The recording at `path`, HDF5 or CSV by its content; gaps refused (see load_recording_file)."""
    return load_recording_file(path).recording


def export_recording_csv(source: Path | str, out: Path | str, *, allow_gaps: bool = False) -> Recording:
    """Write the recording CSV of the recording at `source`; return what was written. An HDF5 recording as
    daq.storage.hdf5_recording.export_csv writes it (gaps refused unless allow_gaps); a recording CSV
    rewritten as read, its metadata kept (`source` added when it has none)."""
    source = Path(source)
    if recording_format(source) is RecordingFormat.HDF5:
        from daq.storage.hdf5_recording import export_csv

        with _hdf5_errors(source):
            return export_csv(source, out, allow_gaps=allow_gaps)
    recording = load_recording_file(source).recording
    recording.metadata = {"source": str(source)} | recording.metadata
    write_recording_csv(out, recording)
    return recording
