"""The API's response models (pydantic), and their construction from the store's records.

Every body a client receives is typed here, so that the OpenAPI schema is a contract clients can be
generated from: a job is `IdentifyJobOut`, `DiagnoseJobOut` or `ValidateJobOut`, told apart by `kind`, each
with its typed
options and result (service.api.results); the bench and a sweep's settings are typed too.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from fastapi import Query
from pydantic import AfterValidator, BaseModel, Field, create_model
from pydantic_core import PydanticCustomError

from daq.sweep.model import SweepProgress
from estimator.sweep import SETTING_NAMES, SweepSettings
from service import free_text
from service.api.results import DiagnoseResult, IdentifyResult, ValidateResult
from service.declarations import echo_fields
from service.jobs.diagnose_job import DiagnoseJobOptions
from service.jobs.identify_job import IdentifyJobOptions
from service.jobs.messages import Progress
from service.jobs.validate_job import ValidateJobOptions
from service.store.jobs import JobRecord
from service.store.models import JobKind, JobStatus

API_PREFIX = "/api/v1"

PageLimit = Annotated[int, Query(ge=1, le=500)]
"""The `limit` query parameter of every list endpoint (jobs, sweeps, scheduled tests)."""
PageOffset = Annotated[int, Query(ge=0, le=2**31)]
"""The `offset` query parameter of every list endpoint."""


def _plain_text(text: str) -> str:
    problem = free_text.problem(text)
    if problem is not None:
        raise PydanticCustomError("control_character", problem)
    return text


FreeText = Annotated[str, AfterValidator(_plain_text)]
"""Every free-text field a client sends (an operator's name): no control characters, bidirectional
overrides or line separators (service.free_text), refused with 422 naming the field."""


class ProgressOut(BaseModel):
    stage: str = Field(description="what the job does now")
    elapsed_s: float
    generation: int | None = Field(None, description="DE generation done (solver de)")
    generations: int | None = None
    best_objective: float | None = Field(None, description="best objective GF so far (solver de)")
    eta_s: float | None = Field(None, description="estimated time left, from the generations done")

    @classmethod
    def of(cls, progress: Progress | dict[str, Any] | None) -> ProgressOut | None:
        if progress is None:
            return None
        return cls.model_validate(progress.as_dict() if isinstance(progress, Progress) else progress)


class JobLinks(BaseModel):
    self: str
    events: str
    cancel: str
    plot_png: str | None = None
    plot_svg: str | None = None
    files: dict[str, str] = Field(
        default_factory=dict,
        description="every file the job wrote, name -> link (a diagnosis: report.md and its PNG plots)",
    )


def options_echo(options_model: type[BaseModel], name: str) -> type[BaseModel]:
    """The options of a job as the API echoes them: the fields, types and defaults of `options_model`
    without its bounds. A job keeps the options it was submitted with; bounds tightened since must not
    make an older job unreadable (they are checked at submit, not when reading)."""
    fields: dict[str, Any] = {
        field_name: (
            field.annotation,
            Field(field.default, description=field.description)
            if field.default_factory is None
            else Field(default_factory=field.default_factory, description=field.description),
        )
        for field_name, field in options_model.model_fields.items()
    }
    model: type[BaseModel] = create_model(name, __doc__="The options of the job (as submitted).", **fields)
    return model


IdentifyOptionsOut = options_echo(IdentifyJobOptions, "IdentifyOptionsOut")
DiagnoseOptionsOut = options_echo(DiagnoseJobOptions, "DiagnoseOptionsOut")
ValidateOptionsOut = options_echo(ValidateJobOptions, "ValidateOptionsOut")


class JobOutBase(BaseModel):
    """What every job carries; `kind` says which options and result (IdentifyJobOut, DiagnoseJobOut)."""

    id: int
    lane: str = Field(description="the lane it was submitted on")
    run_by: str | None = Field(None, description="the instance (lane) that runs or ran it")
    attempts: int = Field(0, description="times it was begun (2 or more: an instance died while running it)")
    kind: str
    status: JobStatus
    options: BaseModel
    input_source: str = Field(description="upload, sweep or recording")
    sweep_id: int | None = None
    progress: ProgressOut | None = None
    result: BaseModel | None = None
    error: str | None = Field(None, description="why the job failed or was cancelled")
    submitted_by: str | None = Field(None, description="id of the key that submitted it (a hash)")
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    links: JobLinks


class IdentifyJobOut(JobOutBase):
    """An identification job (POST /jobs, or POST /sweeps/{id}/jobs)."""

    kind: Literal["identify"] = Field(description="identify")
    options: IdentifyOptionsOut  # type: ignore[valid-type]
    result: IdentifyResult | None = Field(
        None,
        description="once succeeded (and in GET /jobs/{id} only): the shape of `shockbench identify --json`",
    )


class DiagnoseJobOut(JobOutBase):
    """A diagnosis job, the model doctor (POST /diagnoses)."""

    kind: Literal["diagnose"] = Field(description="diagnose")
    options: DiagnoseOptionsOut  # type: ignore[valid-type]
    result: DiagnoseResult | None = Field(
        None,
        description="once succeeded (and in GET /jobs/{id} only): the shape of `shockbench diagnose --json`",
    )


class ValidateJobOut(JobOutBase):
    """A validation job: an identified model against another recording (POST /validations)."""

    kind: Literal["validate"] = Field(description="validate")
    options: ValidateOptionsOut  # type: ignore[valid-type]
    result: ValidateResult | None = Field(
        None,
        description="once succeeded (and in GET /jobs/{id} only): the shape of `shockbench validate --json`",
    )


AnyJobOut = IdentifyJobOut | DiagnoseJobOut | ValidateJobOut
JobOut = Annotated[AnyJobOut, Field(discriminator="kind")]
"""A job of any kind, told apart by `kind`."""

JOB_MODELS: dict[str, type[AnyJobOut]] = {
    JobKind.IDENTIFY.value: IdentifyJobOut,
    JobKind.DIAGNOSE.value: DiagnoseJobOut,
    JobKind.VALIDATE.value: ValidateJobOut,
}
"""The response model of each job kind (service.jobs.kinds.KINDS); a new kind adds its model here."""


def job_view(record: JobRecord, live: Progress | None = None, *, with_result: bool = True) -> AnyJobOut:
    """The job as the API shows it: live progress while it runs, the result once it succeeded."""
    base = f"{API_PREFIX}/jobs/{record.id}"
    return JOB_MODELS[record.kind].model_validate(
        {
            "id": record.id,
            "lane": record.lane,
            "run_by": record.claimed_by,
            "attempts": record.attempts,
            "kind": record.kind,
            "status": record.status,
            "options": record.options,
            "input_source": record.input_source,
            "sweep_id": record.sweep_id,
            "progress": ProgressOut.of(live if live is not None else record.progress),
            "result": record.result if with_result else None,
            "error": record.error,
            "submitted_by": record.submitted_by,
            "created_at": record.created_at,
            "started_at": record.started_at,
            "finished_at": record.finished_at,
            "links": JobLinks(
                self=base,
                events=f"{base}/events",
                cancel=f"{base}/cancel",
                plot_png=f"{base}/plot.png" if "plot.png" in record.artefacts else None,
                plot_svg=f"{base}/plot.svg" if "plot.svg" in record.artefacts else None,
                files={name: f"{base}/files/{name}" for name in record.artefacts},
            ),
        }
    )


class JobList(BaseModel):
    jobs: list[JobOut] = Field(description="newest first, without results (GET a job for its result)")
    total: int
    limit: int
    offset: int


# ---- the job event stream (GET /jobs/{id}/events): the data of each event --------------------------------


class ProgressEvent(ProgressOut):
    """The data of a `progress` event."""

    job_id: int


class ClosingEvent(BaseModel):
    """The data of a `closing` event: the service stops; reconnect, or poll the job."""

    job_id: int
    reason: str


ANY_JOB_SCHEMA = "IdentifyJobOut | DiagnoseJobOut | ValidateJobOut"
"""The schemas an event that carries the job may hold."""

JOB_EVENTS: dict[str, tuple[str, str]] = {
    "state": (
        ANY_JOB_SCHEMA,
        "the job as GET /jobs/{id} returns it: first, and when it starts",
    ),
    "progress": ("ProgressEvent", "while it runs: stage, DE generation, best objective, ETA"),
    "succeeded": (ANY_JOB_SCHEMA, "last: the job with its result"),
    "failed": (ANY_JOB_SCHEMA, "last: the job with the reason in `error`"),
    "cancelled": (ANY_JOB_SCHEMA, "last: the job, cancelled"),
    "closing": ("ClosingEvent", "last, when the service stops first"),
}
"""Event name -> (schema of its JSON data, when it comes)."""


# ---- the bench and its sweeps ----------------------------------------------------------------------------


class SweepProgressOut(BaseModel):
    phase: str = Field(description="connecting, zeroing, sweeping, settling, stopping, done")
    elapsed_s: float = Field(description="seconds into the recorded part of the run")
    total_s: float = Field(description="seconds recorded in all (sweep plus settling)")
    fraction: float = Field(description="elapsed_s / total_s, 0..1")
    frequency_Hz: float = Field(description="the plate's frequency as the drive reports it")
    rows: int = Field(description="recording rows written so far")
    gap_rows: int = Field(description="rows with a missing sample so far")

    @classmethod
    def of(cls, progress: SweepProgress | None) -> SweepProgressOut | None:
        if progress is None:
            return None
        return cls(
            phase=progress.phase.value,
            elapsed_s=progress.elapsed_s,
            total_s=progress.total_s,
            fraction=progress.fraction,
            frequency_Hz=progress.frequency_Hz,
            rows=progress.rows,
            gap_rows=progress.gap_rows,
        )


class BenchOut(BaseModel):
    # The bench in the API (GET /bench): BenchState as JSON. A comment, not a docstring: a docstring would
    # become the schema's description, and the name and schema are part of the OpenAPI contract.
    name: str
    model: str = Field(description="quarter-car or axle")
    simulated: bool = Field(description="the in-process simulated bench (serve --simulated)")
    busy: bool = Field(description="a sweep is running, or the end of the one that ran is being stored")
    sweep_id: int | None = Field(None, description="the running sweep")
    progress: SweepProgressOut | None = Field(None, description="the running sweep's latest progress")


SweepSettingsOut: type[BaseModel] = create_model(
    "SweepSettingsOut",
    __doc__="A sweep's settings as submitted (POST /sweeps without the vehicle file). A setting the record "
    "does not hold (a sweep stored by other means) is null.",
    **echo_fields(SweepSettings, SETTING_NAMES),
    settle_s=(float | None, Field(None, description="recorded after the sweep (s)")),
)
"""The plate's settings as SweepSettings declares them (estimator.sweep), without their bounds."""


class LiveStateEvent(BaseModel):
    """The data of a live stream's `state` event (GET /bench/live)."""

    busy: bool = Field(description="a sweep is running, or the end of the one that ran is being stored")
    sweep_id: int | None = Field(None, description="the running sweep")
    progress: SweepProgressOut | None = Field(None, description="the running sweep's latest progress")
    devices: list[dict[str, str]] = Field(
        default_factory=list, description="GET /bench/devices: each device with its `state` in words"
    )


class LiveSamplesEvent(BaseModel):
    """The data of a live stream's `samples` event: the rows recorded since the last one, decimated."""

    sweep_id: int | None = Field(description="the sweep they belong to")
    t_s: list[float] = Field(description="seconds since the sweep's start command")
    channels: dict[str, list[float | None]] = Field(
        description="recording channel -> displacement (m) per row (x_r plate, x_t wheel, x_s body; an axle "
        "adds _l/_r); null where the recording has a gap"
    )
    missed: int = Field(0, description="decimated rows this stream fell too far behind to get")


class LiveClosingEvent(BaseModel):
    """The data of a live stream's `closing` event: the service stops; reconnect later."""

    reason: str


LIVE_EVENTS: dict[str, tuple[str, str]] = {
    "state": ("LiveStateEvent", "first, on every change of phase or sweep, and at least once a second"),
    "samples": ("LiveSamplesEvent", "while a sweep records, about 20 a second: the rows new since the last"),
    "closing": ("LiveClosingEvent", "last, when the service stops"),
}
"""The events of GET /bench/live: name -> (schema of its JSON data, when it comes)."""


# ---- the service ---------------------------------------------------------------------------------------


class WorkerOut(BaseModel):
    alive: bool
    ready: bool = Field(description="the worker has loaded the estimator and waits for jobs")
    pid: int | None
    restarts: int


class CurrentJobOut(BaseModel):
    id: int
    kind: str = Field(description="identify, diagnose or validate")
    progress: ProgressOut | None


class SyncOut(BaseModel):
    """The lane's local store and its sync to the central database (serve --database without
    --shared-queue)."""

    central: str = Field(description="the central database's URL, password hidden")
    reachable: bool | None = Field(
        description="the central database answered the last sync round (null: none yet)"
    )
    backlog: int = Field(description="finished sweeps and jobs not yet on the central database")
    oldest_pending: datetime | None = Field(description="when the oldest of them finished (UTC)")
    last_error: str | None = Field(description="why the last round did not finish its work, in one line")
    last_contact: datetime | None = Field(description="when a round last reached the central database")
    pushed: int = Field(description="sweeps and jobs pushed since the service started")


class StatusOut(BaseModel):
    service: str = "shockbench"
    version: str
    lane: str = Field(description="this instance's lane (serve --lane)")
    uptime_s: float
    worker: WorkerOut
    queue_length: int = Field(description="jobs waiting for the worker")
    current_job: CurrentJobOut | None
    bench: BenchOut | None = Field(None, description="the bench at a glance (null: the service has none)")
    sync: SyncOut | None = Field(
        None, description="the sync of the lane's local store to the central database (null: no local store)"
    )
