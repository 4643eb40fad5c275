"""A laser channel as an acquisition source: reads its ZX-L amplifier and writes the samples, as channel
displacements in metres, into a ring buffer of its own.

Two kinds of amplifier, told apart by the bench configuration (`LaserConfig.sample_period_s`):

* Streaming: the amplifier samples on its own clock into a ring behind a sample counter
  (drivers.compowayf.layout.streaming_measured_config). Each `poll` reads the counter, then exactly the
  samples taken since the last poll (ZxlAmplifier.read_stream with `since`, in requests of at most 25
  double words), so every sample arrives once, stamped with its device time (sample number x period,
  `Clock.DEVICE`). Samples that left the amplifier's ring before a poll got them are counted in
  `lost_samples` and are absent from the ring buffer: the recorder sees the hole, marks a gap.
* Polled: the amplifier holds only its present value. Each `poll` reads it once and stamps it with the
  host's clock at the middle of the request (`Clock.HOST_MONOTONIC`). The rate is whatever the line allows;
  `statistics().achieved_rate_Hz` says what it was, and the recording carries it.

A lost reply: after a request its amplifier did not answer, OMRON's rule keeps the whole line quiet until
a late reply can no longer come (`LinkSettings.late_reply_s`, 3 s; drivers/compowayf/transport.py). A
`poll` in that wait sends nothing and returns 0 (`line_waits`); the samples the wait costs are a gap in
the recording (streaming: those the amplifier's ring could not hold until the next read, counted in
`lost_samples`; polled: the reads not made), never filled. `line_lost_reply_since_data` tells the sweep's
silence check that the line is in that documented wait (daq/sweep/silence.py).

Errors: every failed read keeps its error in `statistics().last_error` (timeouts included); a source
whose polls are held back by its line's wait after another node's lost reply says so, naming that failure.

Values: `LaserConfig.to_channel_m` of the reading (the recorder subtracts the channel's mean at rest, taken
by the sweep orchestration). An out-of-range reading is NaN (a gap in the recording, never a value).

Devices: the source needs only drivers.interfaces.LaserAmplifier (the ZX-L driver, or an in-process mock
from drivers/mock.py in unit tests).

Threads: `poll` is called from one thread at a time (a line's polling thread, or the simulated pacing);
`statistics` from any.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from daq.bench_config import LaserConfig
from daq.ring_buffer import Clock, RingBuffer
from daq.sources.clock_mapping import DeviceClockMapping
from drivers.compowayf.layout import COUNTER_MODULUS
from drivers.interfaces import LaserAmplifier

DEFAULT_CAPACITY = 1 << 16
"""Ring-buffer samples per source: 65 s at 1 kHz, far more than a recorder ever falls behind."""


@dataclass(frozen=True)
class SourceStatistics:
    """What a source has delivered. Rates in Hz over host time from its first to its newest sample."""

    name: str
    channel: str
    clock: Clock
    reads: int
    failed_reads: int
    samples: int
    lost_samples: int
    """Streaming: samples the amplifier took that no poll got in time (each is a hole in the data)."""
    out_of_range_samples: int
    achieved_rate_Hz: float
    nominal_rate_Hz: float | None
    """The amplifier's own sampling rate (streaming), None for a polled amplifier."""
    last_error: str
    """The newest failure ("ErrorClass: message"), or why the line held this source back; "" if none."""
    line_waits: int = 0
    """Polls that sent nothing: the line was waiting out a late reply (OMRON's wait after no reply)."""


class LaserSource:
    """One laser channel: `poll()` reads the amplifier and appends to `buffer` (1 value per sample, m)."""

    def __init__(
        self,
        laser: LaserConfig,
        amplifier: LaserAmplifier,
        *,
        host_clock: Callable[[], float] = time.monotonic,
        capacity: int = DEFAULT_CAPACITY,
    ) -> None:
        self.laser = laser
        self.amplifier = amplifier
        self.host_clock = host_clock
        measured = amplifier.config.measured
        self.streaming = measured.is_streaming
        self.period_s = measured.sample_period_s if self.streaming else None
        self.buffer = RingBuffer(
            capacity, 1, clock=Clock.DEVICE if self.streaming else Clock.HOST_MONOTONIC, flags=False
        )
        self.mapping = DeviceClockMapping()
        self._lock = threading.Lock()
        self._total_counter: int | None = None  # unwrapped sample counter after the last poll
        self._last_poll_host_s: float | None = None
        self._reads = self._failed = self._samples = self._lost = self._out_of_range = 0
        self._first_sample_host_s = math.nan
        self._last_sample_host_s = math.nan
        self._last_data_host_s: float | None = None  # when the last read brought new samples
        self._last_error = ""
        self._failed_since_data = False
        self._line_waits = 0
        self._unanswered_at_data = amplifier.port.counters.unanswered  # the line's count at the last data

    @property
    def name(self) -> str:
        return self.laser.name

    @property
    def channel(self) -> str:
        return self.laser.channel

    def to_host_s(self, timestamps_s: np.ndarray) -> np.ndarray:
        """Host monotonic seconds of samples read from `buffer` (device-stamped ones through `mapping`)."""
        if self.buffer.clock is Clock.HOST_MONOTONIC:
            return timestamps_s
        return timestamps_s + self.mapping.offset_s

    # ---- polling --------------------------------------------------------------------------------------

    def poll(self) -> int:
        """Read the amplifier once and append what came in; returns the number of new samples. A failed
        read is counted and re-raised (a drivers.compowayf error) for the caller to judge. While the line
        waits out a late reply nothing is sent and 0 is returned (see the module)."""
        port = self.amplifier.port
        if port.quiet_s() > 0:
            with self._lock:
                self._line_waits += 1
                if not self._failed_since_data:
                    self._last_error = f"its line waits out a late reply after {port.last_failure}"
            return 0
        try:
            count = self._poll_stream() if self.streaming else self._poll_present_value()
        except Exception as exc:
            with self._lock:
                self._failed += 1
                self._failed_since_data = True
                self._last_error = f"{type(exc).__name__}: {exc}"
            raise
        return count

    def line_quiet_s(self) -> float:
        """Seconds this source's line must still stay quiet (OMRON's wait after an unanswered request)."""
        return self.amplifier.port.quiet_s()

    def line_lost_reply_since_data(self) -> bool:
        """Whether the line has had a request go unanswered since this source's last new samples, or is
        waiting for a reply now: its silence may then be the line's documented wait, not a dead source."""
        port = self.amplifier.port
        return port.awaiting_reply or port.counters.unanswered != self._unanswered_at_data

    def _channel_m(self, counts: list[int]) -> np.ndarray:
        measured = self.amplifier.config.measured
        readings = np.array([measured.counts_to_m(c) for c in counts], dtype=float)
        return self.laser.sign * (readings - self.laser.zero_m)

    def _poll_present_value(self) -> int:
        started_s = self.host_clock()
        counts = self.amplifier.read_counts(1)
        received_s = self.host_clock()
        stamp_s = 0.5 * (started_s + received_s)
        values = self._channel_m(counts)
        self.buffer.write_block(np.array([stamp_s]), values.reshape(1, 1))
        self._book(1, 0, int(np.isnan(values).sum()), stamp_s, stamp_s, received_s)
        return 1

    def _poll_stream(self) -> int:
        period_s = self.period_s
        assert period_s is not None
        capacity = self.amplifier.config.measured.buffer_length
        if self._total_counter is None:
            read = self.amplifier.read_stream(1)  # the first poll only finds where the counter stands
            new = len(read.counts)
        else:
            since = self._total_counter % COUNTER_MODULUS
            read = self.amplifier.read_stream(capacity, since=since)
            new = (read.counter - since) % COUNTER_MODULUS
        received_s = self.host_clock()
        self._last_poll_host_s = received_s
        total = read.counter if self._total_counter is None else self._total_counter + new
        self._total_counter = total
        taken = min(new, len(read.counts))  # fewer when the ring overwrote the oldest before the read
        lost = new - taken
        if taken == 0:
            self._book(0, lost, 0, math.nan, math.nan, received_s)
            return 0
        numbers = np.arange(total - taken, total, dtype=np.float64)
        device_s = numbers * period_s
        values = self._channel_m(read.counts[:taken][::-1])
        self.mapping.observe(float(device_s[-1]), received_s)
        self.buffer.write_block(device_s, values.reshape(-1, 1))
        host_s = device_s + self.mapping.offset_s
        self._book(taken, lost, int(np.isnan(values).sum()), host_s[0], host_s[-1], received_s)
        return taken

    def _book(
        self, samples: int, lost: int, out_of_range: int, first_s: float, last_s: float, received_s: float
    ) -> None:
        with self._lock:
            self._reads += 1
            self._samples += samples
            self._lost += lost
            self._out_of_range += out_of_range
            if samples:
                if math.isnan(self._first_sample_host_s):
                    self._first_sample_host_s = first_s
                self._last_sample_host_s = last_s
                self._last_data_host_s = received_s
                self._failed_since_data = False
                self._unanswered_at_data = self.amplifier.port.counters.unanswered

    # ---- reporting ------------------------------------------------------------------------------------

    def statistics(self) -> SourceStatistics:
        with self._lock:
            span_s = self._last_sample_host_s - self._first_sample_host_s
            rate = (self._samples - 1) / span_s if self._samples > 1 and span_s > 0 else 0.0
            return SourceStatistics(
                name=self.name,
                channel=self.channel,
                clock=self.buffer.clock,
                reads=self._reads,
                failed_reads=self._failed,
                samples=self._samples,
                lost_samples=self._lost,
                out_of_range_samples=self._out_of_range,
                achieved_rate_Hz=rate,
                nominal_rate_Hz=None if self.period_s is None else 1.0 / self.period_s,
                last_error=self._last_error,
                line_waits=self._line_waits,
            )

    def seconds_since_data(self) -> float:
        """Host seconds since a read last brought new samples (inf before the first): silence detection.
        A streaming amplifier that answers but whose counter stands still is silent too."""
        with self._lock:
            last = self._last_data_host_s
        return math.inf if last is None else self.host_clock() - last
