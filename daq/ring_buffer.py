"""Preallocated multichannel ring buffer for acquisition: one writer, many readers at their own pace.

The laser amplifiers deliver x_s, x_t, x_r per side (6 channels for an axle) at up to 1 kHz; the recorder, a
live display and a watchdog each read the same stream through their own `Reader` with its own cursor.

Storage is allocated once: `capacity × channels` float64 values (the measured quantities in their SI units,
displacements in m), one float64 timestamp per sample (s) and, when asked for, one int32 flag per sample
(status bits of the writer's choosing, 0 = none).

Timestamps and clocks
    Each sample carries a timestamp in seconds. The clock is kept **per buffer** (`RingBuffer.clock`):
    `Clock.DEVICE` when the device stamps its samples (seconds on the device's own time base), else
    `Clock.HOST_MONOTONIC` (seconds of `time.monotonic()` on the host at reception; `host_timestamp_s()`).
    The writer names the clock when it creates the buffer and may repeat it on every write (`clock=`), which
    is checked: timestamps of two clocks never mix in one buffer, so a reader can always subtract them. A
    writer whose time source changes starts a new buffer. Every `ReadResult` carries the buffer's clock.

Indices
    Samples are numbered from 0 in write order (absolute index); sample i lives in slot i % capacity. The
    buffer holds the last `capacity` samples written.

Overrun
    When the writer laps a reader (writes more than `capacity` samples the reader has not read), the samples
    overwritten before the reader got them are lost to that reader: the next `read` reports how many
    (`ReadResult.lost`, the samples skipped just before `first_index`), the reader's statistics and the
    buffer-wide statistics count them, and the reader resumes at the oldest sample still held. Loss is
    never silent: for every reader, samples received + samples lost == samples written since it joined,
    once it has drained.

Threads
    One writer thread, any number of reader threads; a `Reader` belongs to one consumer thread. The writer
    copies into the slots and advances the write index under the buffer's lock (a short hold: one slice
    assignment per array). Readers take the lock only to look at the indices: they copy out without it and
    afterwards discard (and count as lost) any copied sample the writer may have overwritten meanwhile, so
    a slow consumer never stalls the writer and never sees a torn sample.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "BufferStatistics",
    "Clock",
    "ClockMismatchError",
    "ReadResult",
    "Reader",
    "ReaderStatistics",
    "RingBuffer",
    "host_timestamp_s",
]


class Clock(StrEnum):
    """Time base of a buffer's timestamps (all in seconds)."""

    DEVICE = "device"
    """The device's own clock (seconds on its time base, e.g. since the amplifier started sampling)."""
    HOST_MONOTONIC = "host_monotonic"
    """The host's `time.monotonic()` at reception (seconds; no relation to wall-clock time)."""


class ClockMismatchError(ValueError):
    """A write named a different clock than the buffer's."""


def host_timestamp_s() -> float:
    """Host monotonic timestamp (s) for a device without its own clock (`Clock.HOST_MONOTONIC`)."""
    return time.monotonic()


@dataclass(frozen=True, slots=True)
class ReadResult:
    """What one `Reader.read` returns: the new samples in write order and what was lost before them.

    timestamps_s: shape (count,), seconds on `clock`.
    values: shape (count, channels), float64 in the channels' units.
    flags: shape (count,) int32, or None when the buffer keeps no flags.
    lost: samples lost to overrun immediately before `first_index` (0 when the reader kept up).
    first_index: absolute index of the first returned sample (the reader's position when count == 0).
    The arrays are copies owned by the caller.
    """

    timestamps_s: NDArray[np.float64]
    values: NDArray[np.float64]
    flags: NDArray[np.int32] | None
    lost: int
    first_index: int
    clock: Clock

    @property
    def count(self) -> int:
        """Number of samples returned."""
        return int(self.timestamps_s.shape[0])


@dataclass(frozen=True, slots=True)
class ReaderStatistics:
    """Counters of one reader (samples unless noted)."""

    name: str
    read: int
    """Samples delivered to this reader."""
    lost: int
    """Samples this reader lost to overrun."""
    overruns: int
    """Reads that reported a loss (each lap detection counts once)."""
    pending: int
    """Samples written and still held that this reader has not read yet (its backlog)."""
    fill_fraction: float
    """pending / capacity: 1.0 means the next write overruns this reader."""


@dataclass(frozen=True, slots=True)
class BufferStatistics:
    """Buffer-wide counters (samples unless noted)."""

    capacity: int
    channels: int
    total_written: int
    """Samples written since the buffer was made."""
    held: int
    """Samples currently held: min(total_written, capacity)."""
    total_lost: int
    """Samples lost to overrun, summed over all readers (including closed ones)."""
    fill_fraction: float
    """Backlog of the slowest open reader / capacity (0.0 without readers): how close the buffer is to an
    overrun."""
    readers: dict[str, ReaderStatistics] = field(default_factory=dict)


class Reader:
    """An independent cursor on a `RingBuffer`; made by `RingBuffer.reader(name)`. Use from one thread."""

    __slots__ = ("_buffer", "_closed", "_cursor", "_lost", "_overruns", "_read", "name")

    def __init__(self, buffer: RingBuffer, name: str, cursor: int) -> None:
        self._buffer = buffer
        self.name = name
        self._cursor = cursor
        self._read = 0
        self._lost = 0
        self._overruns = 0
        self._closed = False

    @property
    def position(self) -> int:
        """Absolute index of the next sample this reader will get."""
        return self._cursor

    @property
    def lost(self) -> int:
        """Samples this reader has lost to overrun so far."""
        return self._lost

    @property
    def received(self) -> int:
        """Samples delivered to this reader so far."""
        return self._read

    @property
    def overruns(self) -> int:
        """Reads that reported a loss."""
        return self._overruns

    def read(self, max_samples: int | None = None) -> ReadResult:
        """Return the samples written since the last read (at most `max_samples`, oldest first).

        If the writer lapped this reader, the overwritten samples are counted in `ReadResult.lost` (and in
        the statistics) and the read starts at the oldest sample still held.
        """
        if self._closed:
            raise RuntimeError(f"reader {self.name!r} is closed")
        if max_samples is not None and max_samples < 0:
            raise ValueError(f"max_samples must be >= 0, got {max_samples}")
        buf = self._buffer
        capacity = buf.capacity
        with buf._lock:
            head = buf._head
        cursor = self._cursor
        start = max(cursor, head - capacity)
        end = head if max_samples is None else min(head, start + max_samples)
        timestamps, values, flags = buf._copy_out(start, end)
        with buf._lock:
            # Anything below the oldest index held now may have been overwritten while we copied.
            oldest = buf._head - capacity
            if oldest > start:
                drop = min(oldest, end) - start
                timestamps, values = timestamps[drop:], values[drop:]
                if flags is not None:
                    flags = flags[drop:]
                start += drop
            lost = start - cursor
            if lost:
                self._lost += lost
                self._overruns += 1
                buf._total_lost += lost
            self._read += end - start
            self._cursor = end
        return ReadResult(timestamps, values, flags, lost, start, buf.clock)

    def statistics(self) -> ReaderStatistics:
        """This reader's counters."""
        with self._buffer._lock:
            return self._statistics(self._buffer._head)

    def _statistics(self, head: int) -> ReaderStatistics:
        capacity = self._buffer.capacity
        pending = head - max(self._cursor, head - capacity)
        return ReaderStatistics(
            self.name, self._read, self._lost, self._overruns, pending, pending / capacity
        )

    def close(self) -> None:
        """Detach from the buffer (its losses stay in the buffer's total_lost). Idempotent."""
        self._buffer._remove(self)


class RingBuffer:
    """Fixed-capacity multichannel sample ring: one writer, many `Reader`s (see the module docstring).

    capacity: samples held (> 0). channels: values per sample (> 0). clock: time base of the timestamps.
    flags: also keep one int32 flag per sample.
    """

    def __init__(self, capacity: int, channels: int, *, clock: Clock, flags: bool = False) -> None:
        if capacity <= 0 or channels <= 0:
            raise ValueError(f"capacity and channels must be positive, got {capacity} and {channels}")
        self.capacity = int(capacity)
        self.channels = int(channels)
        self.clock = Clock(clock)
        self._timestamps = np.zeros(self.capacity, dtype=np.float64)
        self._values = np.zeros((self.capacity, self.channels), dtype=np.float64)
        self._flags: NDArray[np.int32] | None = np.zeros(self.capacity, dtype=np.int32) if flags else None
        self._head = 0  # absolute index of the next sample to write == total written
        self._total_lost = 0
        self._readers: dict[str, Reader] = {}
        self._lock = threading.Lock()

    @property
    def has_flags(self) -> bool:
        """Whether the buffer keeps a flag per sample."""
        return self._flags is not None

    @property
    def total_written(self) -> int:
        """Samples written since the buffer was made."""
        return self._head

    # ---- writer side -------------------------------------------------------------------------------------

    def write(
        self, timestamp_s: float, values: ArrayLike, flag: int = 0, *, clock: Clock | None = None
    ) -> None:
        """Append one sample: timestamp (s, on the buffer's clock), `channels` values, optional flag."""
        if clock is not None and clock != self.clock:
            raise ClockMismatchError(f"buffer clock is {self.clock}, write says {clock}")
        if len(values) != self.channels:  # type: ignore[arg-type]
            raise ValueError(f"expected {self.channels} values, got {len(values)}")  # type: ignore[arg-type]
        flags = self._flags
        if flags is None and flag:
            raise ValueError("this buffer keeps no flags")
        with self._lock:
            slot = self._head % self.capacity
            self._values[slot] = values
            self._timestamps[slot] = timestamp_s
            if flags is not None:
                flags[slot] = flag
            self._head += 1

    def write_block(
        self,
        timestamps_s: ArrayLike,
        values: ArrayLike,
        flags: ArrayLike | None = None,
        *,
        clock: Clock | None = None,
    ) -> None:
        """Append n samples at once: timestamps (n,) in s, values (n, channels), optional flags (n,).

        Vectorised: at most two slice copies per array (the block may cross the end of the ring). A block
        longer than the capacity keeps only its last `capacity` samples; the earlier ones count as written
        (and as lost to every reader).
        """
        if clock is not None and clock != self.clock:
            raise ClockMismatchError(f"buffer clock is {self.clock}, write says {clock}")
        ts = np.asarray(timestamps_s, dtype=np.float64)
        vals = np.asarray(values, dtype=np.float64)
        n = ts.shape[0] if ts.ndim == 1 else -1
        if vals.shape != (n, self.channels):
            raise ValueError(
                f"expected timestamps (n,) and values (n, {self.channels}), got {ts.shape} and {vals.shape}"
            )
        capacity = self.capacity
        fl = None
        if flags is not None:
            if self._flags is None:
                raise ValueError("this buffer keeps no flags")
            fl = np.asarray(flags)
            if fl.shape != (n,):
                raise ValueError(f"expected flags ({n},), got {fl.shape}")
        skipped = 0
        if n > capacity:  # only the last `capacity` samples survive the write
            skipped = n - capacity
            ts, vals = ts[skipped:], vals[skipped:]
            if fl is not None:
                fl = fl[skipped:]
        kept = n - skipped
        with self._lock:
            start = (self._head + skipped) % capacity
            end = start + kept
            if end <= capacity:
                self._timestamps[start:end] = ts
                self._values[start:end] = vals
                if self._flags is not None:
                    self._flags[start:end] = 0 if fl is None else fl
            else:
                first = capacity - start
                self._timestamps[start:] = ts[:first]
                self._timestamps[: end - capacity] = ts[first:]
                self._values[start:] = vals[:first]
                self._values[: end - capacity] = vals[first:]
                if self._flags is not None:
                    if fl is None:
                        self._flags[start:] = 0
                        self._flags[: end - capacity] = 0
                    else:
                        self._flags[start:] = fl[:first]
                        self._flags[: end - capacity] = fl[first:]
            self._head += n

    # ---- reader side -------------------------------------------------------------------------------------

    def reader(self, name: str, *, from_oldest: bool = False) -> Reader:
        """Register a reader with its own cursor. It starts at the next sample written, or at the oldest
        sample still held with `from_oldest=True`. Names are unique among open readers."""
        with self._lock:
            if name in self._readers:
                raise ValueError(f"a reader named {name!r} is already open")
            cursor = max(0, self._head - self.capacity) if from_oldest else self._head
            reader = Reader(self, name, cursor)
            self._readers[name] = reader
        return reader

    def _remove(self, reader: Reader) -> None:
        with self._lock:
            if self._readers.get(reader.name) is reader:
                del self._readers[reader.name]
            reader._closed = True

    def _copy_out(
        self, start: int, end: int
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int32] | None]:
        """Copy absolute indices [start, end) (end - start <= capacity) into new arrays, without the lock."""
        n = end - start
        capacity = self.capacity
        s = start % capacity
        first = min(n, capacity - s)
        if first == n:
            ts = self._timestamps[s : s + n].copy()
            vals = self._values[s : s + n].copy()
            fl = None if self._flags is None else self._flags[s : s + n].copy()
        else:
            rest = n - first
            ts = np.concatenate((self._timestamps[s:], self._timestamps[:rest]))
            vals = np.concatenate((self._values[s:], self._values[:rest]))
            fl = None if self._flags is None else np.concatenate((self._flags[s:], self._flags[:rest]))
        return ts, vals, fl

    def statistics(self) -> BufferStatistics:
        """A consistent snapshot of the buffer's and every open reader's counters."""
        with self._lock:
            head = self._head
            readers = {name: r._statistics(head) for name, r in self._readers.items()}
            total_lost = self._total_lost
        slowest = max((r.pending for r in readers.values()), default=0)
        return BufferStatistics(
            capacity=self.capacity,
            channels=self.channels,
            total_written=head,
            held=min(head, self.capacity),
            total_lost=total_lost,
            fill_fraction=slowest / self.capacity,
            readers=readers,
        )
