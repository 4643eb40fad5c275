"""What a job function gets in the worker (JobContext) and gives back (JobOutcome), and how it reports
progress (ProgressReporter: stages, and DE generations with an ETA, throttled)."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias, TypeVar

from pydantic import BaseModel
from pydantic.dataclasses import dataclass as checked_dataclass

from estimator.recording import Recording
from estimator.solvers.differential_evolution import DEProgress
from estimator.vehicle import VehicleParameters
from service.jobs.input_error import InputError as InputError  # re-exported: the job kinds raise it from here
from service.jobs.messages import JsonObject, JsonValue, Progress

if TYPE_CHECKING:
    from estimator.output_error import IdentifiedModel

    Companion: TypeAlias = VehicleParameters | IdentifiedModel
else:
    Companion: TypeAlias = Any  # the estimator's model module loads in the worker only

Options = TypeVar("Options", bound=BaseModel)


class ProgressReporter:
    """Turns stages and DE generations into Progress messages. Generations are sent at most every
    `min_interval_s` (DE runs hundreds per second), but always the first and the last."""

    def __init__(
        self,
        send: Callable[[Progress], None],
        min_interval_s: float = 0.2,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._send = send
        self._interval = min_interval_s
        self._clock = clock
        self._start = clock()
        self._stage = "starting"
        self._last_sent = -math.inf
        self._first: tuple[float, int] | None = None
        self._last: Progress | None = None

    def elapsed(self) -> float:
        return self._clock() - self._start

    def stage(self, name: str) -> None:
        """A new stage; the generations reached so far stay in the report (a DE job that goes on to plot
        still says how far DE went)."""
        self._stage = name
        self._first = None
        last = self._last
        self._last = Progress(
            stage=name,
            elapsed_s=self.elapsed(),
            generation=last.generation if last else None,
            generations=last.generations if last else None,
            best_objective=last.best_objective if last else None,
        )
        self._send(self._last)

    def generation(self, p: DEProgress) -> None:
        """The DE progress callback (returns None: never asks DE to stop; cancelling uses the Event)."""
        now = self._clock()
        if self._first is None:
            self._first = (now, p.generation)
        last = p.generation >= p.generations
        if not last and self._first[1] != p.generation and now - self._last_sent < self._interval:
            return
        self._last_sent = now
        eta = None
        t0, g0 = self._first
        if p.generation > g0:
            eta = (now - t0) / (p.generation - g0) * (p.generations - p.generation)
        best = p.best_objective if math.isfinite(p.best_objective) else None
        self._last = Progress(
            stage=self._stage,
            elapsed_s=now - self._start,
            generation=p.generation,
            generations=p.generations,
            best_objective=best,
            eta_s=eta,
        )
        self._send(self._last)


@dataclass
class JobContext:
    job_id: int
    recording: Recording
    vehicle: VehicleParameters
    options: BaseModel
    """The options stored at submit, as the kind's options model read them (JobKindSpec.options_model)."""
    output_dir: Path
    cancel: threading.Event
    progress: ProgressReporter
    companion: Companion = None
    """What the kind's file beside the recording was read into (service.jobs.inputs): the vehicle
    parameters, or a validation's identified model."""

    def options_as(self, model: type[Options]) -> Options:
        """The options, as the kind's model (TypeError when the worker read them with another)."""
        if not isinstance(self.options, model):
            raise TypeError(f"job {self.job_id} carries {type(self.options).__name__}, not {model.__name__}")
        return self.options


@checked_dataclass
class JobOutcome:
    """What a job function gives back; checked when made, so a result that is not a JSON document fails
    the job in the worker (an internal error with its id) instead of the service's write."""

    result: JsonObject
    artefacts: dict[str, str] = field(default_factory=dict)
    """Artefact name -> file name written into JobContext.output_dir."""


def finite_json(value: Any) -> JsonValue:
    """A JSON-able copy with NaN and ±inf replaced by None (JSON has no such numbers)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): finite_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_json(v) for v in value]
    return value
