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
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from daq.formats.hdf5_file import open_for_reading
from daq.formats.recording_csv import write_recording_csv
from daq.formats.vehicle_file import VehicleFile
from estimator.errors import UserError, one_line
from estimator.recording import Recording

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
_STATUS_DTYPE = h5py.string_dtype("utf-8", 16)
_REASON_DTYPE = h5py.string_dtype("utf-8", REASON_BYTES)
_TIME_DTYPE = h5py.string_dtype("utf-8", 40)
_RESERVED = frozenset(
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
_RATE_PREFIX = "rate_Hz."


class RecordingFileError(UserError, ValueError):
    """The file is not a readable shockbench HDF5 recording; the message is one line naming the file."""


class RecordingGapError(RecordingFileError):
    """The recording has gaps (NaN samples) where the caller needs gap-free data."""


def _utc_now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds")


def _software_version() -> str:
    try:
        return importlib_metadata.version("shockbench")
    except importlib_metadata.PackageNotFoundError:
        return "unknown"


def _gap_runs(gap: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges of consecutive True values."""
    edges = np.diff(np.concatenate(([0], gap.astype(np.int8), [0])))
    return list(zip(np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist(), strict=True))


class RecordingWriter:
    """Append blocks of samples to a new HDF5 recording while acquiring; `close` says how it ended.

    path: the file to create (FileExistsError if it exists: a recording is never overwritten).
    channels: the channel names (e.g. QUARTER_CAR_CHANNELS or AXLE_CHANNELS), values in metres.
    sample_time_s: the grid period, s (0.001).
    metadata: root attributes (str/int/float), e.g. bench, sweep, device models and firmware, operator;
    start_time (ISO 8601, UTC) and software_version default to now and the installed shockbench version.
    vehicle: the vehicle file as read at the edge, stored as its source name (vehicle_file) and its text
    verbatim (vehicle_text); the file is not read again here. rates_Hz: the sources whose
    achieved rate close() will record (values here are the nominal rates, NaN if unknown), stored as
    attributes "rate_Hz.<source>". flush_interval_s: recorded time between flushes, s (at most this much
    is lost in a crash).

    Use as a context manager or call close() yourself; leaving the `with` block by an exception closes the
    file as incomplete with the exception as reason, leaving it without close() as incomplete too.
    """

    def __init__(
        self,
        path: Path | str,
        channels: Sequence[str],
        sample_time_s: float,
        metadata: Mapping[str, MetadataValue] | None = None,
        *,
        vehicle: VehicleFile | None = None,
        rates_Hz: Mapping[str, float] | None = None,
        flush_interval_s: float = 1.0,
    ) -> None:
        self.path = Path(path)
        self.channels = tuple(channels)
        if not self.channels:
            raise ValueError("a recording needs at least one channel")
        if len(set(self.channels)) != len(self.channels):
            raise ValueError(f"duplicated channel name in {', '.join(self.channels)}")
        if not all(name and "/" not in name and name.isprintable() for name in self.channels):
            raise ValueError(f"bad channel name in {self.channels!r}")
        if not (math.isfinite(sample_time_s) and sample_time_s > 0):
            raise ValueError(f"sample_time_s must be positive, got {sample_time_s}")
        if not flush_interval_s > 0:
            raise ValueError("flush_interval_s must be positive")
        self.sample_time_s = float(sample_time_s)
        self.flush_interval_s = float(flush_interval_s)
        attrs = self._metadata_attrs(metadata or {}, vehicle)
        self._rate_sources = tuple(rates_Hz or {})
        self._n = 0
        self._flushed = 0
        self._t0: float | None = None
        self._gaps = 0
        self._gap_samples = 0
        self._first_gap_s = math.nan
        self._last_was_gap = False
        self._closed = False

        chunk = max(1, min(65536, round(1.0 / self.sample_time_s)))
        if self.path.exists():
            raise FileExistsError(f"{self.path}: already exists; a recording is never overwritten")
        self._file = h5py.File(self.path, "w-", libver="latest")
        try:
            f = self._file
            for key, value in attrs.items():
                f.attrs[key] = value
            for source, rate in (rates_Hz or {}).items():
                f.attrs.create(_RATE_PREFIX + source, float(rate), dtype="f8")
            f.attrs.create("status", "recording", dtype=_STATUS_DTYPE)
            f.attrs.create("reason", "", dtype=_REASON_DTYPE)
            f.attrs.create("end_time", "", dtype=_TIME_DTYPE)
            for key in ("samples", "gaps", "gap_samples"):
                f.attrs.create(key, 0, dtype="i8")
            f.attrs.create("first_gap_s", math.nan, dtype="f8")

            def resizable(where: h5py.Group, name: str, dtype: str, fill: float, unit: str) -> h5py.Dataset:
                ds = where.create_dataset(
                    name, shape=(0,), maxshape=(None,), chunks=(chunk,), dtype=dtype, fillvalue=fill
                )
                ds.attrs["unit"] = unit
                return ds

            self._time = resizable(f, "time", "f8", math.nan, "s")
            self._flags = resizable(f, "flags", "u1", 0, "bit 0: gap (no measured sample, value NaN)")
            group = f.create_group("channels")
            self._data = {name: resizable(group, name, "f8", math.nan, "m") for name in self.channels}
            self._flushed_ds = f.create_dataset("flushed_samples", data=np.zeros(1, dtype="i8"))
            f.swmr_mode = True
        except BaseException:
            self._file.close()
            raise

    def _metadata_attrs(
        self, metadata: Mapping[str, MetadataValue], vehicle: VehicleFile | None
    ) -> dict[str, Any]:
        attrs: dict[str, Any] = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "channels": ",".join(self.channels),
            "sample_time_s": self.sample_time_s,
            "start_time": _utc_now(),
            "software_version": _software_version(),
        }
        for key, value in metadata.items():
            if key in _RESERVED or key.startswith(_RATE_PREFIX):
                raise ValueError(f"metadata key {key!r} is written by the recorder itself")
            if isinstance(value, bool) or not isinstance(value, str | int | float | np.integer | np.floating):
                raise ValueError(f"metadata {key!r}: {type(value).__name__} is not str, int or float")
            attrs[key] = value
        if vehicle is not None:
            attrs["vehicle_file"] = vehicle.source
            attrs["vehicle_text"] = vehicle.text
        return attrs

    @property
    def samples(self) -> int:
        """Rows appended so far."""
        return self._n

    @property
    def flushed_samples(self) -> int:
        """Rows on disk (a crash now loses samples - flushed_samples rows)."""
        return self._flushed

    @property
    def gaps(self) -> int:
        """Number of gaps (runs of consecutive gap rows) so far."""
        return self._gaps

    def append(
        self,
        time_s: np.ndarray,
        values: Mapping[str, np.ndarray],
        flags: np.ndarray | None = None,
    ) -> None:
        """Append a block: time_s (s, continuing the grid), values[channel] in m (NaN = no measurement).

        flags: per-row uint8 flags, or None. A row with a NaN in any channel gets FLAG_GAP set; a row
        flagged FLAG_GAP must have a NaN somewhere (a gap is never filled silently). Infinite values and
        times off the grid raise ValueError and nothing of the block is written.
        """
        if self._closed:
            raise ValueError(f"{self.path}: recording already closed")
        t = np.asarray(time_s, dtype=float).reshape(-1)
        n = t.size
        if n == 0:
            return
        if set(values) != set(self.channels):
            raise ValueError(
                f"append: channels {', '.join(sorted(values))} differ from {', '.join(self.channels)}"
            )
        block = {name: np.asarray(values[name], dtype=float) for name in self.channels}
        for name, arr in block.items():
            if arr.shape != (n,):
                raise ValueError(f"append: channel {name} has shape {arr.shape}, time has {n} samples")
            if np.any(np.isinf(arr)):
                raise ValueError(f"append: channel {name} has an infinite value")
        t0 = t[0] if self._t0 is None else self._t0
        grid = t0 + (self._n + np.arange(n)) * self.sample_time_s
        off = np.nonzero(~(np.abs(t - grid) <= GRID_TOLERANCE * self.sample_time_s))[0]
        if off.size:
            i = int(off[0])
            raise ValueError(
                f"append: time {t[i]:.6f} s is not on the {self.sample_time_s * 1e3:g} ms grid "
                f"(expected {grid[i]:.6f} s)"
            )
        nan_rows = np.zeros(n, dtype=bool)
        for arr in block.values():
            nan_rows |= np.isnan(arr)
        if flags is None:
            row_flags = np.zeros(n, dtype=np.uint8)
        else:
            row_flags = np.asarray(flags).reshape(-1)
            if row_flags.shape != (n,):
                raise ValueError(f"append: flags has {row_flags.size} values, time has {n} samples")
            if np.any((row_flags < 0) | (row_flags > 255)):
                raise ValueError("append: flags must fit in uint8")
            row_flags = row_flags.astype(np.uint8)
            filled = np.nonzero((row_flags & FLAG_GAP).astype(bool) & ~nan_rows)[0]
            if filled.size:
                raise ValueError(
                    f"append: sample at t = {t[filled[0]]:.6f} s is flagged as a gap but has a value in "
                    "every channel (gaps must be NaN)"
                )
        row_flags |= np.where(nan_rows, FLAG_GAP, 0).astype(np.uint8)

        start, stop = self._n, self._n + n
        for ds in (self._time, self._flags, *self._data.values()):
            ds.resize((stop,))
        self._time[start:stop] = t
        self._flags[start:stop] = row_flags
        for name, arr in block.items():
            self._data[name][start:stop] = arr
        self._t0 = t0
        self._n = stop
        self._count_gaps(t, nan_rows)
        if (self._n - self._flushed) * self.sample_time_s >= self.flush_interval_s - 1e-9:
            self.flush()

    def _count_gaps(self, t: np.ndarray, gap: np.ndarray) -> None:
        runs = _gap_runs(gap)
        if not runs:
            self._last_was_gap = False
            return
        self._gap_samples += int(gap.sum())
        self._gaps += len(runs) - (1 if self._last_was_gap and runs[0][0] == 0 else 0)
        if math.isnan(self._first_gap_s):
            self._first_gap_s = float(t[runs[0][0]])
        self._last_was_gap = bool(gap[-1])

    def flush(self) -> None:
        """Put every appended row on disk (called by append at least once per flush_interval_s)."""
        if self._closed:
            return
        self._file.flush()
        self._flushed_ds[0] = self._n
        self._file.flush()
        self._flushed = self._n

    def close(
        self, complete: bool, reason: str | None = None, rates_Hz: Mapping[str, float] | None = None
    ) -> None:
        """Write the final attributes and close the file.

        complete: True if the sweep ran to its end. reason: why it is incomplete (e.g. "exciter fault
        0x0010"), kept to REASON_BYTES bytes; required when complete is False. rates_Hz: achieved rate of
        each source, Hz; only sources declared at construction (ValueError before anything is written).
        """
        if self._closed:
            raise ValueError(f"{self.path}: recording already closed")
        unknown = sorted(set(rates_Hz or {}) - set(self._rate_sources))
        if unknown:
            raise ValueError(
                f"close: rate source(s) {', '.join(unknown)} not declared when the recording was created "
                f"(declared: {', '.join(self._rate_sources) or 'none'})"
            )
        if not complete and not (reason and reason.strip()):
            raise ValueError("close: an incomplete recording needs a reason")
        text = " ".join((reason or "").split())
        cut = text.encode("utf-8")[:REASON_BYTES].decode("utf-8", errors="ignore")
        attrs = self._file.attrs
        attrs.modify("status", "complete" if complete else "incomplete")
        attrs.modify("reason", cut)
        attrs.modify("end_time", _utc_now())
        attrs.modify("samples", self._n)
        attrs.modify("gaps", self._gaps)
        attrs.modify("gap_samples", self._gap_samples)
        attrs.modify("first_gap_s", self._first_gap_s)
        for source, rate in (rates_Hz or {}).items():
            attrs.modify(_RATE_PREFIX + source, float(rate))
        self.flush()
        self._file.close()
        self._closed = True

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object) -> None:
        if self._closed:
            return
        if exc is not None:
            self.close(False, f"{exc_type.__name__ if exc_type else 'error'}: {exc}".rstrip(": "))
        else:
            self.close(False, "the acquisition ended without closing the recording")


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
        return _gap_runs(self.gap_mask)

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
