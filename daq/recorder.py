"""The recorder: drains every source's ring buffer, puts the channels on the common grid and appends the rows
to the recording on disk while the acquisition runs.

Grid: instant k is `origin_s + k * sample_time_s` on the host's monotonic clock (device-stamped samples are
mapped there by their source); the recording's time column is `k * sample_time_s`, seconds since the
origin. How each channel is interpolated and when a grid instant is a gap: daq/alignment.py.

A row is written once every channel's value at its instant is final (each source has a sample beyond it),
so rows go to disk in order, a block per `step`, without ever being rewritten. A silent source holds the
rows back; `finish(end_s)` then writes every remaining row up to end_s, as gaps where a channel has no data.
The recording file flushes every second of rows (daq/storage/hdf5_writer.py), so a crash loses at most
the last second.

Overruns: a recorder that fell more than a ring buffer behind loses samples; its readers count them
(`statistics().overrun_samples`), and the lost samples become gaps like any other missing sample.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from daq.alignment import ChannelAligner
from daq.live_view import LiveView
from daq.ring_buffer import Reader
from daq.sources.laser_source import LaserSource
from daq.storage.hdf5_recording import RecordingWriter

STREAMING_GAP_PERIODS = 1.5
"""A device-clocked source has a gap where two samples are more than this many periods apart."""
POLLED_GAP_INTERVALS = 2.5
LIVE_SPREAD_S = 0.2
"""At finish, a channel whose newest sample is within this of the newest of all still counts as delivering:
the recording ends where all of those have data, rather than with gap rows for a channel one read behind."""
"""A polled source has a gap where two samples are more than this many typical intervals apart."""


def max_interval_s(source: LaserSource, typical_interval_s: float | None = None) -> float:
    """The longest interval between two samples of `source` that is not a gap (see the constants)."""
    if source.period_s is not None:
        return STREAMING_GAP_PERIODS * source.period_s
    if typical_interval_s is None or not typical_interval_s > 0:
        raise ValueError(f"{source.name}: a polled source needs its typical read interval")
    return POLLED_GAP_INTERVALS * typical_interval_s


@dataclass(frozen=True)
class RecorderStatistics:
    rows: int
    """Rows written to the recording."""
    gap_rows: int
    """Rows with at least one channel missing (NaN, flagged as gaps in the file)."""
    overrun_samples: int
    """Samples the recorder's ring-buffer readers lost because it fell behind."""
    out_of_order_samples: int
    """Samples dropped because they were not later than their source's newest."""


class Recorder:
    """Sources (one per channel) in, rows of the recording out. One thread calls step/finish."""

    def __init__(
        self,
        sources: Sequence[LaserSource],
        writer: RecordingWriter,
        origin_s: float,
        max_intervals_s: Mapping[str, float],
        rest_offsets_m: Mapping[str, float] | None = None,
        live: LiveView | None = None,
    ) -> None:
        """max_intervals_s: per channel, the longest interval between samples that is not a gap
        (`max_interval_s`). rest_offsets_m: per channel, subtracted from every value (the mean at rest),
        so the recording is measured from the static position. live: the screens' decimated copy of the
        rows written (daq.live_view), if any."""
        by_channel = {source.channel: source for source in sources}
        missing = [c for c in writer.channels if c not in by_channel]
        if missing:
            raise ValueError(f"no source for channel(s) {', '.join(missing)}")
        self.writer = writer
        self.sample_time_s = writer.sample_time_s
        self.origin_s = float(origin_s)
        self._sources = [by_channel[c] for c in writer.channels]
        self._readers: list[Reader] = [  # from the oldest held: the samples at rest lead into row 0
            s.buffer.reader(f"recorder {writer.path}", from_oldest=True) for s in self._sources
        ]
        self._aligners = [ChannelAligner(max_intervals_s[s.channel]) for s in self._sources]
        offsets = rest_offsets_m or {}
        self._offsets_m = [float(offsets.get(s.channel, 0.0)) for s in self._sources]
        self.live = live
        self._next_row = 0
        self._gap_rows = 0
        self._overruns = 0
        self.finished = False

    @property
    def rows(self) -> int:
        return self._next_row

    def recorded_until_s(self) -> float:
        """Host time of the next row to write (origin + rows * sample time)."""
        return self.origin_s + self._next_row * self.sample_time_s

    def _drain(self) -> None:
        for source, reader, aligner, offset_m in zip(
            self._sources, self._readers, self._aligners, self._offsets_m, strict=True
        ):
            result = reader.read()
            self._overruns += result.lost
            if result.count:
                aligner.add(source.to_host_s(result.timestamps_s), result.values[:, 0] - offset_m)

    def _write_until(self, end_row: int) -> int:
        if end_row <= self._next_row:
            return 0
        rows = np.arange(self._next_row, end_row)
        grid_s = self.origin_s + rows * self.sample_time_s
        values = {
            channel: aligner.values_at(grid_s)
            for channel, aligner in zip(self.writer.channels, self._aligners, strict=True)
        }
        self.writer.append(rows * self.sample_time_s, values)
        if self.live is not None:
            self.live.add(rows, rows * self.sample_time_s, values)
        gap = np.zeros(rows.size, dtype=bool)
        for column in values.values():
            gap |= np.isnan(column)
        self._gap_rows += int(gap.sum())
        self._next_row = end_row
        next_s = self.origin_s + end_row * self.sample_time_s
        for aligner in self._aligners:
            aligner.discard_before(next_s)
        return rows.size

    def _row_at_or_before(self, time_s: float) -> int:
        """Index of the last grid row at or before time_s, plus one (rows before it are covered)."""
        if not math.isfinite(time_s):
            return 0 if time_s < 0 else self._next_row
        return max(0, math.floor((time_s - self.origin_s) / self.sample_time_s + 1e-9) + 1)

    def step(self) -> int:
        """Drain the sources and write every row whose values are final; returns the rows written."""
        if self.finished:
            return 0
        self._drain()
        final_s = min(aligner.final_until_s for aligner in self._aligners)
        return self._write_until(self._row_at_or_before(final_s))

    def finish(self, end_s: float) -> int:
        """Drain and write every row up to end_s (host time), or up to where every channel still
        delivering has data if that is earlier; rows a silent channel has no data for are gaps. Closes the
        readers; the writer is the caller's to close."""
        if self.finished:
            return 0
        self._drain()
        newest = [aligner.newest_s for aligner in self._aligners]
        live = [n for n in newest if n >= max(newest) - LIVE_SPREAD_S]  # the channels still delivering
        written = self._write_until(self._row_at_or_before(min(end_s, *live)))
        for reader in self._readers:
            reader.close()
        self.finished = True
        return written

    def statistics(self) -> RecorderStatistics:
        return RecorderStatistics(
            rows=self._next_row,
            gap_rows=self._gap_rows,
            overrun_samples=self._overruns,
            out_of_order_samples=sum(a.out_of_order for a in self._aligners),
        )
