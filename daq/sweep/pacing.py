"""Who polls the sources, and how time passes during a sweep.

* `RealtimePacing`: real devices (or simulated ones on their own wall clock). One thread per serial line
  (lasers sharing an RS-485 line take turns on it) polls its sources: streaming amplifiers every
  `poll_interval_s`, polled ones back to back, as fast as the line answers. Time is time.monotonic.
* `SimulatedPacing`: a simulated bench on a manual clock (any `SteppedSimulation`: the service's
  SimulatedBench, or drivers.mock.ManualClock under the mock devices of daq.sweep.mock_devices.MockDevices),
  for tests and `shockbench sweep --simulated`. `wait(dt)` moves the bench's clock in steps of
  `poll_interval_s` and polls every source after each step, so a run is deterministic and needs no sleeps
  (and runs as fast as the machine allows).

Both keep going when a read fails: the source counts it, and the orchestration judges a source that stays
silent (daq/sweep/run.py).
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Protocol

from daq.sources.laser_source import LaserSource

log = logging.getLogger(__name__)

DEFAULT_POLL_INTERVAL_S = 0.02
"""Streaming amplifiers are read every 20 ms: 20 samples per read at 1 kHz, a tenth of their buffer."""
ERROR_BACKOFF_S = 0.01
"""A line's thread waits this long after a failed read before the next."""


class Pacing(Protocol):
    host_clock: Callable[[], float]

    def start(self, lines: Sequence[Sequence[LaserSource]]) -> None:
        """Begin polling; `lines` groups the sources by the port they share."""

    async def wait(self, dt_s: float) -> None:
        """Let dt_s of bench time pass while the sources are polled."""

    def stop(self) -> None:
        """Stop polling (idempotent)."""


def _poll(source: LaserSource) -> bool:
    """One poll; a failure is counted by the source and reported by the orchestration, not raised."""
    try:
        source.poll()
    except Exception:  # every driver fault: counted in the source's statistics
        return False
    return True


class RealtimePacing:
    def __init__(self, poll_interval_s: float = DEFAULT_POLL_INTERVAL_S) -> None:
        self.poll_interval_s = poll_interval_s
        self.host_clock: Callable[[], float] = time.monotonic
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def start(self, lines: Sequence[Sequence[LaserSource]]) -> None:
        for index, line in enumerate(lines):
            thread = threading.Thread(
                target=self._run_line, args=(tuple(line),), name=f"laser line {index}", daemon=True
            )
            self._threads.append(thread)
            thread.start()

    def _run_line(self, sources: tuple[LaserSource, ...]) -> None:
        streaming = all(source.streaming for source in sources)
        next_s = time.monotonic()
        while not self._stop.is_set():
            ok = all([_poll(source) for source in sources])
            if not ok or any(source.line_quiet_s() > 0 for source in sources):  # or a late-reply wait
                self._stop.wait(ERROR_BACKOFF_S)
            if streaming:
                next_s += self.poll_interval_s
                delay = next_s - time.monotonic()
                if delay < -self.poll_interval_s:  # fell behind: do not try to catch up in a burst
                    next_s = time.monotonic()
                self._stop.wait(max(0.0, delay))

    async def wait(self, dt_s: float) -> None:
        await asyncio.sleep(dt_s)

    def stop(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=5.0)
            if thread.is_alive():
                log.warning("%s did not stop within 5 s", thread.name)
        self._threads.clear()


class SimulationClock(Protocol):
    def now_s(self) -> float:
        """Bench time in seconds."""


class SteppedSimulation(Protocol):
    """What SimulatedPacing needs of a simulated bench. A protocol, so that daq/ does not import the
    simulators (or the service module that assembles them into a bench)."""

    realtime: bool
    clock: SimulationClock

    def advance(self, dt_s: float) -> None:
        """Move the bench's clock by dt_s and let every simulated device act on it."""


class SimulatedPacing:
    def __init__(self, bench: SteppedSimulation, poll_interval_s: float = DEFAULT_POLL_INTERVAL_S) -> None:
        if bench.realtime:
            raise ValueError("SimulatedPacing needs a bench on a manual clock; use RealtimePacing")
        self.bench = bench
        self.poll_interval_s = poll_interval_s
        self.host_clock: Callable[[], float] = bench.clock.now_s
        self._sources: tuple[LaserSource, ...] = ()
        self._owed_s = 0.0

    def start(self, lines: Sequence[Sequence[LaserSource]]) -> None:
        self._sources = tuple(source for line in lines for source in line)

    def _step(self) -> None:
        self.bench.advance(self.poll_interval_s)
        for source in self._sources:
            _poll(source)

    async def wait(self, dt_s: float) -> None:
        self._owed_s += dt_s
        while self._owed_s >= self.poll_interval_s - 1e-12:
            self._owed_s -= self.poll_interval_s
            await asyncio.to_thread(self._step)

    def stop(self) -> None:
        self._sources = ()
