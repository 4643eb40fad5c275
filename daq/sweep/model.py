"""What a sweep is asked to do, what it reports while it runs, and what it leaves behind."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from daq.formats.vehicle_file import VehicleFile
from daq.sources.laser_source import SourceStatistics
from daq.sweep.timing import TIMING_NAMES, SweepTiming
from estimator.declared import declared
from estimator.errors import InvalidValueError, UserError
from estimator.sweep import SweepSettings

SAMPLE_TIME_S = 0.001
"""The recording's grid: 1 ms."""
DEFAULT_SETTLE_S: float = SweepTiming.settle_s
"""Recorded after the sweep's end, while the vehicle comes to rest (declared in daq.sweep.timing)."""
DEFAULT_REST_S: float = SweepTiming.rest_s
"""Sensors read at rest before the sweep: their mean is the channel's zero; the clocks are mapped."""


class SweepError(UserError):
    """The sweep could not begin; the plate did not move and nothing was written. One line; `field` names
    the request's field to blame when there is one."""


@dataclass(frozen=True)
class SweepRequest:
    """One sweep: the plate's settings, the vehicle on the bench, who runs it.

    settle_s: recorded after the sweep ends (s). rest_s: read at rest beforehand (s) to zero the channels
    and map the amplifiers' clocks. vehicle: the vehicle file as read at the edge (its text goes into the
    recording verbatim); None records a sweep without one (a soak test of an empty plate).
    A request is what was asked; daq.sweep.plan checks it against a bench once, and a sweep runs a plan.
    """

    sweep: SweepSettings = field(default_factory=SweepSettings)
    vehicle: VehicleFile | None = None
    operator: str = ""
    settle_s: float = DEFAULT_SETTLE_S
    rest_s: float = DEFAULT_REST_S

    def __post_init__(self) -> None:
        for name in TIMING_NAMES:
            value = getattr(self, name)
            (found,) = (d.declared for d in declared(SweepTiming, (name,)))
            if not (math.isfinite(value) and found.admits(value)):
                raise InvalidValueError(f"{name} must be within {found.range_text()} s, got {value}")

    @property
    def recorded_s(self) -> float:
        """Seconds recorded from the start command: sweep plus settling."""
        return self.sweep.duration_s + self.settle_s


class SweepPhase(StrEnum):
    CONNECTING = "connecting"
    ZEROING = "zeroing"
    SWEEPING = "sweeping"
    SETTLING = "settling"
    STOPPING = "stopping"
    DONE = "done"


@dataclass(frozen=True)
class SweepProgress:
    """A progress event: phase, seconds into the recorded part of the run and its total, the plate's
    frequency (Hz) as the drive reports it, rows written and rows with a gap so far."""

    phase: SweepPhase
    elapsed_s: float
    total_s: float
    frequency_Hz: float
    rows: int
    gap_rows: int
    sources: tuple[SourceStatistics, ...] = ()
    """What each laser has delivered so far (samples, rate, failed reads, last error)."""

    @property
    def fraction(self) -> float:
        return 0.0 if self.total_s <= 0 else min(1.0, max(0.0, self.elapsed_s / self.total_s))


class StopKind(StrEnum):
    """How the plate was stopped at the end of a run."""

    END_OF_SWEEP = "end_of_sweep"
    """The sweep ran out; a stop command followed as a matter of course."""
    CONTROLLED = "controlled"
    EMERGENCY = "emergency"
    NOT_STARTED = "not_started"
    """The plate never moved (the run failed before the start command)."""
    WATCHDOG = "watchdog"
    """Neither stop command reached the drive; its watchdog stops the plate once the keep-alive ends."""


@dataclass(frozen=True)
class SweepOutcome:
    """What a run left: the recording file (complete or not, and why), how the plate was stopped, and
    what each source and the recorder delivered."""

    path: Path | None
    complete: bool
    reason: str
    stop: StopKind
    rows: int
    gap_rows: int
    overrun_samples: int
    sources: tuple[SourceStatistics, ...]
    cpu_s: float = 0.0
    """Process CPU time spent from connecting to the end (s)."""
    wall_s: float = 0.0

    def summary(self) -> str:
        """One line for an operator."""
        state = "complete" if self.complete else f"INCOMPLETE ({self.reason})"
        rates = ", ".join(f"{s.channel} {s.achieved_rate_Hz:.0f} Hz" for s in self.sources)
        return (
            f"{self.path}: {state}; {self.rows} rows, {self.gap_rows} gap rows; plate stop: {self.stop}; "
            f"rates: {rates or 'none'}"
        )
