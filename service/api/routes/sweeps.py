"""Sweeps on the bench: start one (checked against the safety envelope before anything moves), follow it,
abort it, download its recording as CSV, and run an identification job on it.

The checks and the start are service.api.sweep_launch's (the inspection-line scheduler starts sweeps the
same way). The sweep runs in the bench's own thread; when it ends, that thread stores the outcome
(complete, or failed/aborted with the reason) through the SweepStore.
"""

from __future__ import annotations

import asyncio
import shutil
import tempfile
from datetime import datetime
from pathlib import Path as FilePath
from typing import TYPE_CHECKING, Annotated

from fastapi import APIRouter, Body, Path, Query, Request, Response
from fastapi.responses import FileResponse
from pydantic import BaseModel, ConfigDict, Field
from starlette.background import BackgroundTask

from service.access import Principal
from service.api.auth import Operator, Viewer
from service.api.contract import created, download
from service.api.errors import ApiError, responses
from service.api.quotas import QUOTA_RESPONSES, job_quota
from service.api.routes.bench import require_bench
from service.api.routes.jobs import job_out
from service.api.schemas import (
    API_PREFIX,
    DiagnoseJobOut,
    IdentifyJobOut,
    PageLimit,
    PageOffset,
    SweepProgressOut,
    SweepSettingsOut,
)
from service.api.sweep_launch import SweepIn, launch_sweep
from service.api.sweep_recordings import accept_sweep_job, export, recording_path
from service.bench_control import BenchController
from service.jobs.diagnose_job import DiagnoseJobOptions
from service.jobs.identify_job import IdentifyJobOptions
from service.store.models import JobKind, SweepStatus
from service.store.sweeps import SweepRecord, SweepStore

if TYPE_CHECKING:
    from service.report import ReportInput

router = APIRouter(tags=["sweeps"])

SweepId = Annotated[int, Path(ge=1, le=2**62, description="sweep id")]


class SweepLinks(BaseModel):
    self: str
    abort: str
    recording_csv: str
    recording_h5: str
    jobs: str
    report_pdf: str = Field(description="the test's report (PDF) once an identification succeeded")
    report_html: str = Field(description="the same report as one self-contained HTML page")


class SweepTestOut(BaseModel):
    """What the operator recorded about the test when starting it (each null when not given)."""

    vehicle_id: str | None = Field(None, description="VIN or registration")
    tyre_pressure_bar: float | None = Field(None, description="tyre pressure measured (bar)")
    operator_name: str | None = Field(None, description="who ran the test")


class SweepOut(BaseModel):
    id: int
    lane: str = Field(description="the lane whose bench ran it")
    bench: str
    status: SweepStatus = Field(description="requested, running, complete, failed or aborted")
    settings: SweepSettingsOut = Field(description="the sweep settings and settle_s as submitted")
    test: SweepTestOut = Field(description="the vehicle id, tyre pressure and operator recorded with it")
    latest_job_id: int | None = Field(None, description="the newest identification job on this sweep")
    complete: bool = Field(description="the recording holds the whole sweep without gaps")
    reason: str | None = Field(None, description="why the sweep failed or was aborted")
    operator: str | None = Field(None, description="id of the key that requested it (a hash)")
    recording_file: str | None = Field(None, description="the HDF5 recording's file name in the data dir")
    progress: SweepProgressOut | None = Field(None, description="live while it runs")
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    links: SweepLinks

    @classmethod
    def of(
        cls, record: SweepRecord, bench: BenchController | None = None, latest_job_id: int | None = None
    ) -> SweepOut:
        progress = None
        if bench is not None and not record.finished:
            state = bench.state()
            if state.busy and state.sweep_id == str(record.id):
                progress = SweepProgressOut.of(state.progress)
        base = f"{API_PREFIX}/sweeps/{record.id}"
        return cls(
            id=record.id,
            lane=record.lane,
            bench=record.bench,
            status=record.status,
            settings=SweepSettingsOut.model_validate(record.settings),
            test=SweepTestOut.model_validate(record.settings),
            latest_job_id=latest_job_id,
            complete=record.complete,
            reason=record.reason,
            operator=record.operator,
            recording_file=FilePath(record.recording_path).name if record.recording_path else None,
            progress=progress,
            created_at=record.created_at,
            started_at=record.started_at,
            finished_at=record.finished_at,
            links=SweepLinks(
                self=base,
                abort=f"{base}/abort",
                recording_csv=f"{base}/recording.csv",
                recording_h5=f"{base}/recording.h5",
                jobs=f"{base}/jobs",
                report_pdf=f"{base}/report.pdf",
                report_html=f"{base}/report.html",
            ),
        )


class SweepList(BaseModel):
    sweeps: list[SweepOut] = Field(description="newest first")
    total: int
    limit: int
    offset: int


class SweepJobIn(IdentifyJobOptions):
    """Options of the identification job (as for POST /jobs)."""

    model_config = ConfigDict(extra="forbid")


class SweepDiagnosisIn(DiagnoseJobOptions):
    """Options of the diagnosis (as for POST /diagnoses)."""

    model_config = ConfigDict(extra="forbid")


# ---- helpers ---------------------------------------------------------------------------------------------


def _store(request: Request) -> SweepStore:
    store: SweepStore = request.app.state.services.sweeps
    return store


async def load_sweep(request: Request, sweep_id: int) -> SweepRecord:
    record = await asyncio.to_thread(_store(request).get, sweep_id)
    if record is None:
        raise ApiError(404, f"no sweep {sweep_id}")
    return record


async def sweep_outs(request: Request, records: list[SweepRecord]) -> list[SweepOut]:
    """The sweeps as the API shows them, each with its newest identification job (one query for all)."""
    services = request.app.state.services
    latest = await asyncio.to_thread(
        services.jobs.latest_of_sweeps, [r.id for r in records], JobKind.IDENTIFY.value
    )
    return [SweepOut.of(r, services.bench, latest.get(r.id)) for r in records]


async def sweep_out(request: Request, record: SweepRecord) -> SweepOut:
    return (await sweep_outs(request, [record]))[0]


def _export_to_temp(record: SweepRecord) -> tuple[FilePath, FilePath]:
    h5 = recording_path(record)
    folder = FilePath(tempfile.mkdtemp(prefix=f"sweep-{record.id}-"))
    try:
        csv = folder / f"sweep-{record.id}.csv"
        export(h5, csv)
        return folder, csv
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise


# ---- routes ----------------------------------------------------------------------------------------------


@router.post(
    "/sweeps",
    status_code=201,
    response_model=SweepOut,
    operation_id="start_sweep",
    responses=created("sweep") | responses(400, 401, 403, 409, 422, 503),
)
async def start_sweep(request: Request, response: Response, body: SweepIn, principal: Operator) -> SweepOut:
    """Start a sweep. Checked before anything moves: the settings (422 naming the field, e.g.
    amplitude_m above the bench's safety envelope), the vehicle file (422, field vehicle_toml); 409 while
    the bench runs another sweep. Answers 201 with Location: the sweep, to poll."""
    bench = require_bench(request)
    services = request.app.state.services
    data_dir = services.settings.data_dir
    record = await asyncio.to_thread(
        launch_sweep, bench, services.sweeps, data_dir, body, principal.key_id, services.wake_scheduler
    )
    out = await sweep_out(request, record)
    response.headers["Location"] = out.links.self
    return out


@router.get(
    "/sweeps", response_model=SweepList, operation_id="list_sweeps", responses=responses(401, 403, 422)
)
async def list_sweeps(
    request: Request,
    _principal: Viewer,
    status: SweepStatus | None = None,
    vehicle_id: Annotated[str | None, Query(min_length=1, max_length=40)] = None,
    lane: Annotated[str | None, Query(max_length=100, description="only this lane's")] = None,
    limit: PageLimit = 50,
    offset: PageOffset = 0,
) -> SweepList:
    """Sweeps, newest first; `vehicle_id`: only that vehicle's tests (case does not matter)."""
    records, total = await asyncio.to_thread(
        _store(request).list_sweeps,
        status=status,
        vehicle_id=vehicle_id,
        lane=lane,
        limit=limit,
        offset=offset,
    )
    sweeps = await sweep_outs(request, records)
    return SweepList(sweeps=sweeps, total=total, limit=limit, offset=offset)


@router.get(
    "/sweeps/{sweep_id}",
    response_model=SweepOut,
    operation_id="get_sweep",
    responses=responses(401, 403, 404, 422),
)
async def get_sweep(request: Request, sweep_id: SweepId, _principal: Viewer) -> SweepOut:
    """Status (with live progress while it runs), settings, and why it failed or was aborted."""
    return await sweep_out(request, await load_sweep(request, sweep_id))


@router.post(
    "/sweeps/{sweep_id}/abort",
    status_code=202,
    response_model=SweepOut,
    operation_id="abort_sweep",
    responses=responses(401, 403, 404, 409, 422, 503),
)
async def abort_sweep(request: Request, sweep_id: SweepId, _principal: Operator) -> SweepOut:
    """Controlled stop of a running sweep (202; it ends within a moment as aborted, its recording kept).
    409 if the sweep is not running."""
    bench = require_bench(request)
    record = await load_sweep(request, sweep_id)
    if record.finished:
        raise ApiError(409, f"sweep {sweep_id} has already ended ({record.status.value})")
    if not bench.abort(str(sweep_id)):
        raise ApiError(409, f"sweep {sweep_id} is not running on the bench")
    return await sweep_out(request, record)


@router.get(
    "/sweeps/{sweep_id}/recording.csv",
    response_class=FileResponse,
    operation_id="get_sweep_recording_csv",
    responses=download("text/csv", "the recording CSV (t,x_s,x_t,x_r with '# key: value' metadata)")
    | responses(401, 403, 404, 409, 422),
)
async def sweep_recording_csv(request: Request, sweep_id: SweepId, _principal: Viewer) -> FileResponse:
    """The sweep's recording as a recording CSV (t,x_s,x_t,x_r with '# key: value' metadata). 409 until
    the sweep has ended; 422 (code recording_gaps) when the recording has gaps a CSV cannot hold."""
    record = await load_sweep(request, sweep_id)
    folder, csv = await asyncio.to_thread(_export_to_temp, record)
    return FileResponse(
        csv,
        media_type="text/csv",
        filename=csv.name,
        background=BackgroundTask(shutil.rmtree, folder, ignore_errors=True),
    )


@router.get(
    "/sweeps/{sweep_id}/recording.h5",
    response_class=FileResponse,
    operation_id="get_sweep_recording_h5",
    responses=download(
        "application/octet-stream", "the recording as acquisition wrote it (HDF5, gaps flagged)"
    )
    | responses(401, 403, 404, 409, 422),
)
async def sweep_recording_h5(request: Request, sweep_id: SweepId, _principal: Viewer) -> FileResponse:
    """The sweep's recording as acquisition wrote it (HDF5, with its gaps flagged, the vehicle file and
    the metadata). 409 until the sweep has ended."""
    h5 = recording_path(await load_sweep(request, sweep_id))
    return FileResponse(h5, media_type="application/octet-stream", filename=f"sweep-{sweep_id}.h5")


async def report_input(request: Request, sweep_id: int) -> ReportInput:
    """What the sweep's report is made from: 404 without the sweep, or before an identification of it
    succeeded. (service.report is imported here, when a report is asked for: it loads matplotlib, which the
    service's start-up need not wait for.)"""
    from service.report.source import stored_input, stored_test

    services = request.app.state.services
    test = await asyncio.to_thread(stored_test, services.database, sweep_id)
    if test is None:
        raise ApiError(404, f"no sweep {sweep_id}")
    if test.identification is None:
        raise ApiError(
            404,
            f"sweep {sweep_id} has no identification result yet; its report follows once one succeeded "
            f"(POST {API_PREFIX}/sweeps/{sweep_id}/jobs runs one)",
        )
    return await asyncio.to_thread(stored_input, test, services.version)


@router.get(
    "/sweeps/{sweep_id}/report.pdf",
    response_class=Response,
    operation_id="get_sweep_report_pdf",
    responses=download("application/pdf", "the test's report, from the sweep's newest identification")
    | responses(401, 403, 404, 422),
)
async def sweep_report_pdf(request: Request, sweep_id: SweepId, _principal: Viewer) -> Response:
    """The test's report as a PDF (service.report): the vehicle and test record, the verdict per corner
    with its thresholds, the lane figures, the damper curve, the sweep over time and frequency, masses and
    stiffnesses with their intervals, the model doctor's summary and the result's hash-chain record. From
    the sweep's newest succeeded identification; 404 while it has none."""
    from service.report import report_pdf

    pdf = await asyncio.to_thread(report_pdf, await report_input(request, sweep_id))
    disposition = f'inline; filename="sweep-{sweep_id}-report.pdf"'
    return Response(pdf, media_type="application/pdf", headers={"Content-Disposition": disposition})


@router.get(
    "/sweeps/{sweep_id}/report.html",
    response_class=Response,
    operation_id="get_sweep_report_html",
    responses=download("text/html", "the test's report as one self-contained HTML page")
    | responses(401, 403, 404, 422),
)
async def sweep_report_html(request: Request, sweep_id: SweepId, _principal: Viewer) -> Response:
    """The report of GET .../report.pdf as one HTML page that loads nothing (its plots inside it): sent
    with a policy that lets it load nothing either."""
    from service.report import policy, report_html

    page = await asyncio.to_thread(report_html, await report_input(request, sweep_id))
    return Response(
        page, media_type="text/html; charset=utf-8", headers={"Content-Security-Policy": policy()}
    )


@router.post(
    "/sweeps/{sweep_id}/jobs",
    status_code=201,
    response_model=IdentifyJobOut,
    operation_id="submit_sweep_identify",
    responses=created("identify job") | responses(400, 401, 403, 404, 409, 422) | QUOTA_RESPONSES,
)
async def identify_sweep(
    request: Request,
    response: Response,
    sweep_id: SweepId,
    principal: Operator,
    options: Annotated[SweepJobIn | None, Body()] = None,
) -> IdentifyJobOut:
    """An identification job on the sweep's recording (JSON body: the options of POST /jobs, all
    optional). 409 until the sweep has ended. Answers 201 with Location: the job."""
    job_options = IdentifyJobOptions.model_validate((options or SweepJobIn()).model_dump())
    out = await _job_on_sweep(request, response, sweep_id, principal, job_options, JobKind.IDENTIFY)
    return out  # type: ignore[return-value]


@router.post(
    "/sweeps/{sweep_id}/diagnoses",
    status_code=201,
    response_model=DiagnoseJobOut,
    operation_id="submit_sweep_diagnose",
    responses=created("diagnose job") | responses(400, 401, 403, 404, 409, 422) | QUOTA_RESPONSES,
)
async def diagnose_sweep(
    request: Request,
    response: Response,
    sweep_id: SweepId,
    principal: Operator,
    options: Annotated[SweepDiagnosisIn | None, Body()] = None,
) -> DiagnoseJobOut:
    """The model doctor on the sweep's recording (JSON body: the options of POST /diagnoses, all
    optional). 409 until the sweep has ended. Answers 201 with Location: the job."""
    job_options = DiagnoseJobOptions.model_validate((options or SweepDiagnosisIn()).model_dump())
    out = await _job_on_sweep(request, response, sweep_id, principal, job_options, JobKind.DIAGNOSE)
    return out  # type: ignore[return-value]


async def _job_on_sweep(
    request: Request,
    response: Response,
    sweep_id: int,
    principal: Principal,
    options: IdentifyJobOptions | DiagnoseJobOptions,
    kind: JobKind,
) -> IdentifyJobOut | DiagnoseJobOut:
    """Queue a job of `kind` on the sweep's recording; the 201's Location is the job. 429 (Retry-After)
    when the key has as many jobs queued or running as allowed."""
    services = request.app.state.services
    record = await load_sweep(request, sweep_id)
    job = await asyncio.to_thread(
        accept_sweep_job,
        services.settings,
        services.jobs,
        record,
        options,
        principal.key_id,
        kind,
        job_quota(services.settings, principal),
    )
    services.manager.enqueue(job)
    out = job_out(request, job)
    response.headers["Location"] = out.links.self
    return out  # type: ignore[return-value]
