"""Writing a recording while the bench acquires: RecordingWriter appends blocks of samples to a new HDF5
file, flushing every second of recorded time, and `close` says how the recording ended (the layout and
its crash safety: daq.storage.hdf5_layout)."""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping, Sequence
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from daq.formats.vehicle_file import VehicleFile
from daq.storage.hdf5_layout import (
    FLAG_GAP,
    FORMAT_NAME,
    FORMAT_VERSION,
    GRID_TOLERANCE,
    RATE_PREFIX,
    REASON_BYTES,
    REASON_DTYPE,
    RESERVED_ATTRIBUTES,
    STATUS_DTYPE,
    TIME_DTYPE,
    MetadataValue,
    gap_runs,
)


def _utc_now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds")


def _software_version() -> str:
    try:
        return importlib_metadata.version("shockbench")
    except importlib_metadata.PackageNotFoundError:
        return "unknown"


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
                f.attrs.create(RATE_PREFIX + source, float(rate), dtype="f8")
            f.attrs.create("status", "recording", dtype=STATUS_DTYPE)
            f.attrs.create("reason", "", dtype=REASON_DTYPE)
            f.attrs.create("end_time", "", dtype=TIME_DTYPE)
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
            if key in RESERVED_ATTRIBUTES or key.startswith(RATE_PREFIX):
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
        runs = gap_runs(gap)
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
            attrs.modify(RATE_PREFIX + source, float(rate))
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
