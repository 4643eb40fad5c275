"""Honest read-rate bookkeeping: how fast measured values actually come back from an amplifier.

The acquisition layer must know the sample rate it really gets (serial latency, retries and the amplifier's
own response time all count), not the rate it asked for. Every measured-value read is timed from just before
the request to just after the reply (retries included); the rate is successful reads over the wall time
from the start of the first read to the end of the last one, so idle time between reads lowers it too.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class ReadRate:
    """Achieved read performance since the last reset.

    reads: successful measured-value reads; failures: reads that raised; samples: values delivered
    (a buffer read of N elements delivers N); elapsed_s: first read start to last read end;
    reads_per_s / samples_per_s: reads / samples over elapsed_s (0 when nothing was read);
    mean_latency_s / max_latency_s: request-to-reply time of the successful reads.
    """

    reads: int
    failures: int
    samples: int
    elapsed_s: float
    reads_per_s: float
    samples_per_s: float
    mean_latency_s: float
    max_latency_s: float


class RateMeter:
    """Accumulates read timings; thread safe. `clock` is a monotonic seconds counter (perf_counter)."""

    def __init__(self, clock: Callable[[], float] = time.perf_counter) -> None:
        self.clock = clock
        self._lock = threading.Lock()
        self.reset()

    def reset(self) -> None:
        with self._lock:
            self._reads = 0
            self._failures = 0
            self._samples = 0
            self._first_start_s: float | None = None
            self._last_end_s: float | None = None
            self._latency_sum_s = 0.0
            self._latency_max_s = 0.0

    def record(self, started_s: float, finished_s: float, samples: int, ok: bool) -> None:
        """Book one read that ran from started_s to finished_s (clock seconds)."""
        with self._lock:
            if self._first_start_s is None:
                self._first_start_s = started_s
            self._last_end_s = finished_s
            if not ok:
                self._failures += 1
                return
            latency_s = finished_s - started_s
            self._reads += 1
            self._samples += samples
            self._latency_sum_s += latency_s
            self._latency_max_s = max(self._latency_max_s, latency_s)

    def report(self) -> ReadRate:
        with self._lock:
            elapsed_s = 0.0
            if self._first_start_s is not None and self._last_end_s is not None:
                elapsed_s = max(0.0, self._last_end_s - self._first_start_s)
            per_s = 1.0 / elapsed_s if elapsed_s > 0 else 0.0
            return ReadRate(
                reads=self._reads,
                failures=self._failures,
                samples=self._samples,
                elapsed_s=elapsed_s,
                reads_per_s=self._reads * per_s,
                samples_per_s=self._samples * per_s,
                mean_latency_s=self._latency_sum_s / self._reads if self._reads else 0.0,
                max_latency_s=self._latency_max_s,
            )
