"""What the service and its worker process say to each other over their pipe: typed, picklable messages.

Service -> worker: RunJob, CancelJob, Shutdown. Worker -> service: WorkerReady, then per job JobStarted,
any number of JobProgress, and exactly one of JobSucceeded, JobFailed, JobCancelled. The service adds
WorkerExited itself when the pipe closes (the worker died or stopped).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any


@dataclass(frozen=True)
class RunJob:
    job_id: int
    kind: str
    recording_path: str
    vehicle_path: str
    output_dir: str
    options: dict[str, Any]


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

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class JobProgress:
    job_id: int
    progress: Progress


@dataclass(frozen=True)
class JobSucceeded:
    job_id: int
    result: dict[str, Any]
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
