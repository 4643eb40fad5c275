"""The API's response models (pydantic), and their construction from the store's records."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from fastapi import Query
from pydantic import BaseModel, Field

from service.jobs.messages import Progress
from service.store.jobs import JobRecord
from service.store.models import JobStatus

API_PREFIX = "/api/v1"

PageLimit = Annotated[int, Query(ge=1, le=500)]
"""The `limit` query parameter of every list endpoint (jobs, sweeps, scheduled tests)."""
PageOffset = Annotated[int, Query(ge=0, le=2**31)]
"""The `offset` query parameter of every list endpoint."""


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


class JobOut(BaseModel):
    id: int
    kind: str = Field(description="identify or diagnose")
    status: JobStatus
    options: dict[str, Any]
    input_source: str = Field(description="upload, or sweep")
    sweep_id: int | None = None
    progress: ProgressOut | None = None
    result: dict[str, Any] | None = Field(
        None,
        description="identify: curves (velocity_m_s, force_N, tanh parameters, outliers per corner), "
        "masses_kg, tyre_damping_Ns_per_m, inspection figures, objective, certified_gap, gap_m; the "
        "shape of `shockbench identify --json`. diagnose: gap_before_m, steps (effect, gap_before_m, "
        "gap_after_m, parameters, evidence), gap_after_m, unexplained; the shape of `shockbench diagnose "
        "--json`",
    )
    error: str | None = Field(None, description="why the job failed or was cancelled")
    submitted_by: str | None = Field(None, description="id of the key that submitted it (a hash)")
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    links: JobLinks

    @classmethod
    def of(cls, record: JobRecord, live: Progress | None = None, *, with_result: bool = True) -> JobOut:
        base = f"{API_PREFIX}/jobs/{record.id}"
        return cls(
            id=record.id,
            kind=record.kind,
            status=record.status,
            options=record.options,
            input_source=record.input_source,
            sweep_id=record.sweep_id,
            progress=ProgressOut.of(live if live is not None else record.progress),
            result=record.result if with_result else None,
            error=record.error,
            submitted_by=record.submitted_by,
            created_at=record.created_at,
            started_at=record.started_at,
            finished_at=record.finished_at,
            links=JobLinks(
                self=base,
                events=f"{base}/events",
                cancel=f"{base}/cancel",
                plot_png=f"{base}/plot.png" if "plot.png" in record.artefacts else None,
                plot_svg=f"{base}/plot.svg" if "plot.svg" in record.artefacts else None,
                files={name: f"{base}/files/{name}" for name in record.artefacts},
            ),
        )


class JobList(BaseModel):
    jobs: list[JobOut] = Field(description="newest first, without results (GET a job for its result)")
    total: int
    limit: int
    offset: int


class WorkerOut(BaseModel):
    alive: bool
    ready: bool = Field(description="the worker has loaded the estimator and waits for jobs")
    pid: int | None
    restarts: int


class CurrentJobOut(BaseModel):
    id: int
    kind: str
    progress: ProgressOut | None


class StatusOut(BaseModel):
    service: str = "shockbench"
    version: str
    uptime_s: float
    worker: WorkerOut
    queue_length: int = Field(description="jobs waiting for the worker")
    current_job: CurrentJobOut | None
    bench: dict[str, Any] | None = Field(None, description="the bench and its devices (acquisition layer)")
