"""The live view of a running sweep: a decimated copy of the rows the recorder writes, for screens.

The operator page draws the plate, wheel and body channels while the sweep records. It must not slow the
acquisition, however many screens watch: the recorder hands each block of rows it has written to
`LiveView.add` (one strided copy of a few rows, under a lock held for microseconds), and every screen reads
what is new with its own cursor (`since`), at its own pace, without touching the recorder. The view keeps
the newest `capacity_rows` decimated rows only; a reader that fell further behind gets the newest and a
count of what it missed.

Decimation keeps every `every`-th row of the recording's grid (row index divisible by `every`): 1 kHz
rows at every=10 give 100 points per second of signal, enough for a chart of a 0-20 Hz sweep. It is for
display only; the recording on disk is untouched.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

DEFAULT_EVERY = 10
"""Keep every 10th row: 100 points per second of a 1 kHz recording."""
DEFAULT_CAPACITY_ROWS = 6000
"""Decimated rows kept: one minute at 100 points per second."""


@dataclass(frozen=True)
class LiveRows:
    """What a reader gets from `LiveView.since`: the rows after its cursor."""

    cursor: int
    """Pass it to the next `since` call."""
    time_s: np.ndarray
    """Seconds since the sweep's start command, one per row."""
    channels: dict[str, np.ndarray]
    """Channel name -> displacement (m) per row; NaN where the recording has a gap."""
    missed: int
    """Rows the reader never got because it fell more than the view's capacity behind."""
    run: int
    """Which sweep the rows belong to (`LiveView.start` numbers them); a reader seeing it change starts
    its chart afresh."""
    label: str
    """What the owner called the run when it started it (the service: the sweep id)."""


class LiveView:
    """Decimated rows of the running sweep, written by the recorder's thread, read by any number of others."""

    def __init__(self, *, every: int = DEFAULT_EVERY, capacity_rows: int = DEFAULT_CAPACITY_ROWS) -> None:
        if every < 1 or capacity_rows < 1:
            raise ValueError("every and capacity_rows must be >= 1")
        self.every = every
        self.capacity_rows = capacity_rows
        self._lock = threading.Lock()
        self._run = 0
        self._label = ""
        self._channels: tuple[str, ...] = ()
        self._time_s = np.empty(0)
        self._values = np.empty((0, 0))
        self._end = 0  # rows ever added in this run (decimated); the cursor space

    def start(self, channels: Sequence[str], label: str = "") -> None:
        """A new sweep begins: forget the last one's rows. Until the first call, `add` keeps nothing."""
        with self._lock:
            self._run += 1
            self._label = label
            self._channels = tuple(channels)
            self._time_s = np.empty(0)
            self._values = np.empty((0, len(self._channels)))
            self._end = 0

    def add(self, rows: np.ndarray, time_s: np.ndarray, values: Mapping[str, np.ndarray]) -> None:
        """The recorder wrote rows `rows` (grid indices) at `time_s` with `values` per channel: keep the
        decimated ones. Channels the view was not started with are ignored."""
        keep = np.flatnonzero(np.asarray(rows) % self.every == 0)
        if keep.size == 0:
            return
        with self._lock:
            if not self._channels:
                return
            block = np.column_stack([np.asarray(values[c], dtype=float)[keep] for c in self._channels])
            times = np.asarray(time_s, dtype=float)[keep]
            self._time_s = np.concatenate([self._time_s, times])[-self.capacity_rows :]
            self._values = np.concatenate([self._values, block])[-self.capacity_rows :]
            self._end += keep.size

    def since(self, cursor: int, run: int | None = None) -> LiveRows:
        """The rows added after `cursor` in run `run` (all held rows when the run changed or is None)."""
        with self._lock:
            if run != self._run:
                cursor = 0
            held_from = self._end - self._time_s.size
            start = max(cursor, held_from)
            first = start - held_from
            return LiveRows(
                cursor=self._end,
                time_s=self._time_s[first:].copy(),
                channels={c: self._values[first:, i].copy() for i, c in enumerate(self._channels)},
                missed=max(0, held_from - cursor),
                run=self._run,
                label=self._label,
            )
