"""Reading a recording back: everything in the file with its gaps (load_recording, StoredRecording), the
recording as the estimator sees it (read_recording: gaps refused, or the longest gap-free stretch), and
its export to the recording CSV (export_csv). A file still being written, or whose writer died, is read up
to its last flush (daq.storage.hdf5_layout, "Crash safety")."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from daq.formats.hdf5_file import open_for_reading
from daq.formats.recording_csv import write_recording_csv
from daq.storage.hdf5_layout import (
    FLAG_GAP,
    NOT_CLOSED_REASON,
    MetadataValue,
    RecordingFileError,
    RecordingGapError,
    gap_runs,
)
from estimator.errors import one_line
from estimator.recording import Recording


@dataclass
class StoredRecording:
    """Everything in a recording file, gaps included (NaN in channels, FLAG_GAP in flags).

    time_s in s, channels in m, flags uint8 per row; metadata: the root attributes as str/int/float, with
    status ("complete"/"incomplete"), reason, samples, gaps and gap_samples reflecting the rows read.
    """

    path: Path
    time_s: np.ndarray
    channels: dict[str, np.ndarray]
    flags: np.ndarray
    sample_time_s: float
    metadata: dict[str, MetadataValue] = field(default_factory=dict)

    @property
    def gap_mask(self) -> np.ndarray:
        return (self.flags & FLAG_GAP).astype(bool)

    @property
    def gap_runs(self) -> list[tuple[int, int]]:
        """[start, stop) row ranges of the gaps."""
        return gap_runs(self.gap_mask)

    @property
    def complete(self) -> bool:
        return self.metadata.get("status") == "complete"

    def gap_free_stretches(self) -> list[tuple[int, int]]:
        """[start, stop) row ranges between gaps, in time order."""
        stretches, start = [], 0
        for g0, g1 in self.gap_runs:
            if g0 > start:
                stretches.append((start, g0))
            start = g1
        if start < self.time_s.size:
            stretches.append((start, self.time_s.size))
        return stretches

    def gap_message(self) -> str:
        """One line: how many gaps and where the first is."""
        runs = self.gap_runs
        if not runs:
            return "no gaps"
        n_samples = int(self.gap_mask.sum())
        return (
            f"{len(runs)} gap(s) ({n_samples} sample(s) without a measurement), the first at "
            f"t = {self.time_s[runs[0][0]]:.3f} s"
        )


def _python_value(value: Any) -> MetadataValue:
    if isinstance(value, bytes | np.bytes_):
        return bytes(value).rstrip(b"\0").decode("utf-8", errors="replace")
    if isinstance(value, np.bool_ | bool):
        return int(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.ndarray):
        return ",".join(str(_python_value(v)) for v in value.reshape(-1))
    return value if isinstance(value, str | int | float) else str(value)


def load_recording(path: Path | str) -> StoredRecording:
    """Read a complete, incomplete or still-being-written recording with its gaps (RecordingFileError)."""
    path = Path(path)
    if not path.is_file():
        raise RecordingFileError(f"{path}: no such file")
    if not h5py.is_hdf5(path):
        raise RecordingFileError(f"{path}: not an HDF5 file")
    try:
        with open_for_reading(path) as f:
            meta = {key: _python_value(f.attrs[key]) for key in f.attrs}
            for name in ("time", "flags", "channels", "flushed_samples"):
                if name not in f:
                    raise RecordingFileError(f"{path}: not a shockbench recording (no dataset '{name}')")
            names = [c for c in str(meta.get("channels", "")).split(",") if c] or sorted(f["channels"])
            missing = [c for c in names if c not in f["channels"]]
            if missing:
                raise RecordingFileError(f"{path}: no dataset for channel(s) {', '.join(missing)}")
            datasets = [f["time"], f["flags"], *(f["channels"][c] for c in names)]
            for ds in datasets:
                ds.refresh()
            f["flushed_samples"].refresh()
            n = min(ds.shape[0] for ds in datasets)
            n = min(n, int(f["flushed_samples"][0]))
            time_s = np.asarray(f["time"][:n], dtype=float)
            flags = np.asarray(f["flags"][:n], dtype=np.uint8)
            channels = {c: np.asarray(f["channels"][c][:n], dtype=float) for c in names}
    except RecordingFileError:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:  # h5py: HDF5 errors
        raise RecordingFileError(f"{path}: cannot read the recording ({one_line(exc)})") from None
    if not np.all(np.isfinite(time_s)):
        bad = int(np.argmin(np.isfinite(time_s)))
        raise RecordingFileError(f"{path}: time is not finite at row {bad}")
    if meta.get("status") not in ("complete", "incomplete"):
        meta["status"] = "incomplete"
        meta["reason"] = NOT_CLOSED_REASON
    if "sample_time_s" in meta:
        sample_time_s = float(meta["sample_time_s"])
    elif n > 1:
        sample_time_s = float((time_s[-1] - time_s[0]) / (n - 1))
    else:
        raise RecordingFileError(f"{path}: no sample_time_s attribute")
    stored = StoredRecording(path, time_s, channels, flags, sample_time_s, meta)
    runs = stored.gap_runs
    meta["samples"] = n
    meta["gaps"] = len(runs)
    meta["gap_samples"] = int(stored.gap_mask.sum())
    meta["first_gap_s"] = float(time_s[runs[0][0]]) if runs else math.nan
    return stored


def read_recording(
    path: Path | str, *, allow_gaps: bool = False
) -> tuple[Recording, dict[str, MetadataValue], np.ndarray]:
    """Read a recording as the estimator sees it: (Recording, metadata, flags per row).

    A recording with gaps raises RecordingGapError (naming the first gap and the count) unless allow_gaps
    is True: then the longest gap-free stretch is returned and metadata["gap_free_stretch"] says which.
    Recording.metadata holds the metadata as strings. Errors: RecordingFileError, one line.
    """
    stored = load_recording(path)
    meta = dict(stored.metadata)
    start, stop = 0, stored.time_s.size
    if stored.gap_runs:
        if not allow_gaps:
            raise RecordingGapError(
                f"{stored.path}: {stored.gap_message()}; use allow_gaps (--allow-gaps) to take the "
                "longest gap-free stretch"
            )
        stretches = stored.gap_free_stretches()
        if not stretches:
            raise RecordingGapError(f"{stored.path}: every sample is a gap")
        start, stop = max(stretches, key=lambda s: s[1] - s[0])
        meta["gap_free_stretch"] = (
            f"t = {stored.time_s[start]:.6f} to {stored.time_s[stop - 1]:.6f} s, the longest of "
            f"{len(stretches)} gap-free stretches; the file has {stored.gap_message()}"
        )
    if stop - start < 3:
        raise RecordingFileError(f"{stored.path}: only {stop - start} usable samples; a recording needs 3")
    recording = Recording(
        stored.time_s[start:stop].copy(),
        {name: values[start:stop].copy() for name, values in stored.channels.items()},
        {key: str(value) for key, value in meta.items()},
    )
    return recording, meta, stored.flags[start:stop].copy()


CSV_SKIPPED_METADATA = ("vehicle_text", "format", "format_version", "channels")
"""Attributes left out of the CSV's '# key: value' lines (the vehicle text spans lines; it stays in the
HDF5 file, the CSV keeps vehicle_file)."""


def export_csv(h5_path: Path | str, csv_path: Path | str, *, allow_gaps: bool = False) -> Recording:
    """Write the recording CSV (daq/formats/recording_csv) of an HDF5 recording; return what was written.

    The CSV has no way to mark a missing sample, so a recording with gaps raises RecordingGapError (first
    gap time, number of gaps) unless allow_gaps: then only the longest gap-free stretch is written and the
    '# gap_free_stretch:' line says which stretch and how many gaps the file has. Metadata become
    '# key: value' lines (one line each, newlines replaced by spaces), with source set to the HDF5 path.
    """
    recording, meta, _ = read_recording(h5_path, allow_gaps=allow_gaps)
    lines = {"source": str(h5_path)}
    for key, value in meta.items():
        if key in CSV_SKIPPED_METADATA:
            continue
        lines[key] = " ".join(str(value).split())
    recording.metadata = lines
    write_recording_csv(csv_path, recording)
    return recording
