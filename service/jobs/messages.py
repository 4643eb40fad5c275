"""What the service and its worker process say to each other over their pipe: typed, picklable messages.

Service -> worker: RunJob, CancelJob, Shutdown. Worker -> service: WorkerReady, then per job JobStarted,
any number of JobProgress, and exactly one of JobSucceeded, JobFailed, JobCancelled. The service adds
WorkerExited itself when the pipe closes (the worker died or stopped).

Every message is a pydantic dataclass: its fields are checked when it is made (a job result that is not a
JSON document fails in the worker that made it, not in the service that stores it), and it still pickles
over the pipe and is built positionally. A job's options and result travel as JSON documents (JsonObject):
they are what the database stores and the API returns, unchanged; the kind's options model reads the
options in the worker (service.jobs.kinds), and the API's result models describe the result.
"""

from __future__ import annotations

from dataclasses import asdict, field
from typing import TypeAlias

from pydantic import JsonValue
from pydantic.dataclasses import dataclass

JsonObject: TypeAlias = dict[str, JsonValue]
"""A JSON object: what a job's options are stored as and its result is written as."""


@dataclass(frozen=True)
class RunJob:
    job_id: int
    kind: str
    recording_path: str
    vehicle_path: str
    """The companion file (service.jobs.inputs): the vehicle file, or a validation's model."""
    output_dir: str
    options: JsonObject
    """As stored at submit; the worker reads them with the kind's options model."""


@dataclass(frozen=True)
class CancelJob:
    job_id: int


@dataclass(frozen=True)
class Shutdown:
    pass


@dataclass(frozen=True)
class WorkerReady:
    pid: int


@dataclass(frozen=True)
class JobStarted:
    job_id: int


@dataclass(frozen=True)
class Progress:
    """Where a job is. stage: what it does now ('reading input', 'identifying', 'differential evolution',
    'plotting' ...). The generation fields are set while an evolutionary solver runs; eta_s is the time
    left estimated from the generations done so far."""

    stage: str
    elapsed_s: float
    generation: int | None = None
    generations: int | None = None
    best_objective: float | None = None
    eta_s: float | None = None

    def as_dict(self) -> JsonObject:
        """The progress as the database keeps it and the API shows it (ProgressOut)."""
        return asdict(self)


@dataclass(frozen=True)
class JobProgress:
    job_id: int
    progress: Progress


@dataclass(frozen=True)
class JobSucceeded:
    job_id: int
    result: JsonObject
    """The kind's result as JSON (e.g. `shockbench identify --json`), stored and served as it is."""
    artefacts: dict[str, str] = field(default_factory=dict)
    """Artefact name (e.g. 'plot.png') -> file name in the job's output folder."""


@dataclass(frozen=True)
class JobFailed:
    job_id: int
    reason: str


@dataclass(frozen=True)
class JobCancelled:
    job_id: int


@dataclass(frozen=True)
class WorkerExited:
    """Made by the service, not sent by the worker: the pipe to worker `incarnation` closed."""

    incarnation: int
    exitcode: int | None


ToWorker = RunJob | CancelJob | Shutdown
FromWorker = WorkerReady | JobStarted | JobProgress | JobSucceeded | JobFailed | JobCancelled
