"""Text progress for long CLI runs. Sweeps: one line redrawn in place on a terminal; on a pipe or a log
file, a plain line at each phase change and every tenth of the run, so logs stay readable. A DE's
generations (identify's DE, the refinement that ends a diagnosis): one line redrawn at most ~50 times."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from daq.sweep.model import SweepProgress
    from estimator.solvers.differential_evolution import DEProgress


BAR_WIDTH = 30


class SweepProgressBar:
    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stderr
        self.interactive = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last_phase: str | None = None
        self._last_tenth = -1
        self._drawn = False

    def __call__(self, progress: SweepProgress) -> None:
        line = self.render(progress)
        tenth = int(progress.fraction * 10)
        if self.interactive:
            self.stream.write("\r" + line.ljust(100))
            self._drawn = True
        elif progress.phase != self._last_phase or tenth != self._last_tenth:
            self.stream.write(line + "\n")
        self._last_phase, self._last_tenth = str(progress.phase), tenth
        self.stream.flush()

    @staticmethod
    def render(progress: SweepProgress) -> str:
        filled = round(progress.fraction * BAR_WIDTH)
        bar = "#" * filled + "-" * (BAR_WIDTH - filled)
        gaps = f", {progress.gap_rows} gap rows" if progress.gap_rows else ""
        return (
            f"[{bar}] {progress.fraction * 100:5.1f}% {progress.phase:<10} "
            f"{progress.elapsed_s:6.1f}/{progress.total_s:.1f} s  plate {progress.frequency_Hz:5.2f} Hz  "
            f"{progress.rows} rows{gaps}"
        )

    def close(self) -> None:
        """End the redrawn line (call once the run is over)."""
        if self._drawn:
            self.stream.write("\n")
            self.stream.flush()
            self._drawn = False


def de_progress_line(label: str, p: DEProgress) -> None:
    """A DE's progress after generation p on one stderr line after `label`, redrawn at most ~50 times a run
    and ended with its last generation."""
    step = max(1, p.generations // 50)
    if p.generation % step and p.generation != p.generations:
        return
    done = int(BAR_WIDTH * p.generation / p.generations)
    sys.stderr.write(
        f"\r{label} [{'#' * done}{'.' * (BAR_WIDTH - done)}] generation {p.generation}/{p.generations}"
        f"  best objective {p.best_objective:.6g}"
    )
    if p.generation == p.generations:
        sys.stderr.write("\n")
    sys.stderr.flush()
