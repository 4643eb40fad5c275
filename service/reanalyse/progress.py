"""What `shockbench reanalyse` shows while it runs: on a terminal, one bar redrawn in place with the count,
the rate and the time left (a failure is printed above it as a line of its own); elsewhere (a pipe, a log
file), one plain line per finished analysis. The Dask dashboard's address is said once, when there is one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TextIO

from service.free_text import escaped
from service.reanalyse.task import Outcome

BAR_WIDTH = 30
"""Characters of the bar (as the sweep's bar, service.cli.progress)."""


def outcome_line(number: int, total: int, outcome: Outcome) -> str:
    """The plain line of one finished analysis."""
    task = outcome.task
    said = f"ok in {outcome.seconds:.1f} s" if outcome.ok else f"failed: {outcome.reason}"
    return f"[{number}/{total}] {task.item.name} {task.analysis.value}: {said}"


def bar_line(done: int, total: int, rate_per_s: float, failed: int) -> str:
    """`[#####-----] 40/100  12.3/s  ETA 5 s  2 failed`."""
    fraction = done / total if total else 1.0
    filled = round(fraction * BAR_WIDTH)
    eta = f"ETA {(total - done) / rate_per_s:.0f} s" if rate_per_s > 0 and done < total else "ETA -"
    failures = f"  {failed} failed" if failed else ""
    return f"[{'#' * filled}{'-' * (BAR_WIDTH - filled)}] {done}/{total}  {rate_per_s:.1f}/s  {eta}{failures}"


class RunProgress:
    """Told each finished analysis with its number and the total (`__call__`); `clock` is injectable for
    tests."""

    def __init__(self, stream: TextIO, clock: Callable[[], float] = time.perf_counter) -> None:
        self.stream = stream
        self.interactive = bool(getattr(stream, "isatty", lambda: False)())
        self.clock = clock
        self.started = clock()
        self.done = 0
        self.total = 0
        self.failed = 0

    def say(self, line: str) -> None:
        """A line of its own (above the bar on a terminal)."""
        self.stream.write(("\r\x1b[K" if self.interactive else "") + escaped(line) + "\n")
        if self.interactive and self.done:
            self._draw()
        self.stream.flush()

    def dashboard(self, link: str | None) -> None:
        if link:
            self.say(f"Dask dashboard: {link}")

    def __call__(self, number: int, total: int, outcome: Outcome) -> None:
        if not self.done:
            self.started = self.clock()  # the rate counts from the first result: the cluster's start left out
        self.done, self.total = number, total
        self.failed += not outcome.ok
        if not self.interactive:
            self.stream.write(escaped(outcome_line(number, total, outcome)) + "\n")
        elif not outcome.ok:
            self.say(outcome_line(number, total, outcome))
            return
        else:
            self._draw()
        self.stream.flush()

    def _draw(self) -> None:
        elapsed = self.clock() - self.started
        rate = (self.done - 1) / elapsed if elapsed > 0 else 0.0  # those that finished after the first
        self.stream.write("\r\x1b[K" + bar_line(self.done, self.total, rate, self.failed))

    def close(self) -> None:
        """End the bar's line (on a terminal)."""
        if self.interactive and self.done:
            self.stream.write("\n")
            self.stream.flush()
