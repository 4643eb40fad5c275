"""Jobs: submit (one upload endpoint per job kind, made from the registry in service.jobs.kinds), list,
read with progress and result, plot, cancel.

(No `from __future__ import annotations` here: the submit endpoint's signature is built from each kind's
options model at run time, and FastAPI must see real annotations.)
"""

import asyncio
from pathlib import Path as FilePath
from typing import Annotated

from fastapi import APIRouter, Form, Path, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse

from service.api.auth import Operator, Viewer
from service.api.contract import created, download, upload_encoding, upload_model
from service.api.errors import ApiError, responses
from service.api.intake import accept_upload
from service.api.quotas import QUOTA_RESPONSES, STORAGE_RESPONSES, job_quota
from service.api.schemas import API_PREFIX, JOB_MODELS, JobList, JobOut, PageLimit, PageOffset, job_view
from service.jobs.kinds import KINDS, JobKindSpec
from service.store.jobs import JobRecord
from service.store.models import JobStatus

JobId = Annotated[int, Path(ge=1, le=2**62, description="job id")]
PLOT_MEDIA = {"png": "image/png", "svg": "image/svg+xml"}
FILE_MEDIA = {
    ".md": "text/markdown; charset=utf-8",
    ".json": "application/json",
    **{f".{k}": v for k, v in PLOT_MEDIA.items()},
}
FILE_MEDIA_TYPES = (
    "text/markdown",
    "image/png",
    "image/svg+xml",
    "application/json",
    "application/octet-stream",
)
"""What GET /jobs/{id}/files/{name} may answer with (FILE_MEDIA, else octet-stream)."""


async def load_job(request: Request, job_id: int) -> JobRecord:
    record = await asyncio.to_thread(request.app.state.services.jobs.get, job_id)
    if record is None:
        raise ApiError(404, f"no job {job_id}")
    return record


def job_out(request: Request, record: JobRecord, *, with_result: bool = True) -> JobOut:
    return job_view(
        record, request.app.state.services.manager.live_progress(record.id), with_result=with_result
    )


def _submit_endpoint(spec: JobKindSpec, router: APIRouter) -> None:
    options_model = spec.options_model
    body_model = upload_model(spec)
    allowed = set(body_model.model_fields)

    async def submit(
        request: Request,
        response: Response,
        principal: Operator,
        upload: Annotated[body_model, Form(media_type="multipart/form-data")],  # type: ignore[valid-type]
    ) -> JobOut:
        unknown = sorted(set((await request.form()).keys()) - allowed)
        if unknown:
            raise ApiError(
                422, f"unknown field '{unknown[0]}' (known: {', '.join(sorted(allowed))})", field=unknown[0]
            )
        options = options_model.model_validate(
            {name: getattr(upload, name) for name in options_model.model_fields}
        )
        recording = upload.recording  # type: ignore[attr-defined]
        vehicle = getattr(upload, spec.companion.field)  # the vehicle file, or a validation's model
        services = request.app.state.services
        record = await run_in_threadpool(
            accept_upload,
            services.settings,
            services.jobs,
            spec,
            options,
            (recording.filename, recording.file),
            (vehicle.filename, vehicle.file),
            principal,
            job_quota(services.settings, principal),
        )
        services.manager.enqueue(record)
        out = job_out(request, record)
        response.headers["Location"] = out.links.self
        return out

    submit.__doc__ = (
        f"{spec.summary}. Multipart upload: the recording CSV, its {spec.companion.field} file and the "
        "options. The input "
        "is checked now (422 naming the field); the job is queued and runs in the worker process. "
        "Answers 201 with Location: the job, to poll or to follow at its events link. 429 (Retry-After) "
        "when the key has as many jobs queued or running as allowed; 507 when the data directory is "
        "short of free disk."
    )
    router.add_api_route(
        spec.submit_path,
        submit,
        methods=["POST"],
        status_code=201,
        response_model=JOB_MODELS[spec.name],
        name=f"submit_{spec.name}",
        operation_id=f"submit_{spec.name}",
        summary=f"Submit a {spec.name} job",
        responses=created(f"{spec.name} job")
        | responses(400, 401, 403, 413, 422)
        | QUOTA_RESPONSES
        | STORAGE_RESPONSES,
        openapi_extra={
            "requestBody": {"content": {"multipart/form-data": {"encoding": upload_encoding(spec)}}}
        },
    )


def router() -> APIRouter:
    r = APIRouter(tags=["jobs"])
    for spec in KINDS.values():
        _submit_endpoint(spec, r)

    @r.get("/jobs", response_model=JobList, operation_id="list_jobs", responses=responses(401, 403, 422))
    async def list_jobs(
        request: Request,
        _principal: Viewer,
        status: JobStatus | None = None,
        kind: Annotated[str | None, Query(max_length=32)] = None,
        lane: Annotated[str | None, Query(max_length=100, description="only this lane's")] = None,
        limit: PageLimit = 50,
        offset: PageOffset = 0,
    ) -> JobList:
        """Jobs, newest first, without their results."""
        records, total = await asyncio.to_thread(
            request.app.state.services.jobs.list_jobs,
            status=status,
            kind=kind,
            lane=lane,
            limit=limit,
            offset=offset,
        )
        jobs = [job_out(request, r, with_result=False) for r in records]
        return JobList(jobs=jobs, total=total, limit=limit, offset=offset)

    @r.get(
        "/jobs/{job_id}",
        response_model=JobOut,
        operation_id="get_job",
        responses=responses(401, 403, 404, 422),
    )
    async def get_job(request: Request, job_id: JobId, _principal: Viewer) -> JobOut:
        """Status, progress (live while it runs), and when it succeeded the result: curves, tanh
        parameters, masses, tyre damping, inspection figures, objective and gaps. Poll this, or follow
        the events link."""
        return job_out(request, await load_job(request, job_id))

    @r.post(
        "/jobs/{job_id}/cancel",
        response_model=JobOut,
        operation_id="cancel_job",
        responses={200: {"description": "the queued job, now cancelled"}}
        | {202: {"model": JobOut, "description": "cancel requested; the running job stops shortly"}}
        | responses(401, 403, 404, 409, 422),
    )
    async def cancel_job(request: Request, response: Response, job_id: JobId, _principal: Operator) -> JobOut:
        """Cancel a queued job (200, cancelled) or a running one (202: its worker stops it within seconds;
        follow the job until it says cancelled). 409 if the job has already finished."""
        before = await load_job(request, job_id)
        if before.status.finished:
            raise ApiError(409, f"job {job_id} has already finished ({before.status.value})")
        record = await request.app.state.services.manager.cancel(job_id)
        if record is None:
            raise ApiError(404, f"no job {job_id}")
        if not record.status.finished:
            response.status_code = 202
        return job_out(request, record)

    for fmt, media in PLOT_MEDIA.items():
        _plot_endpoint(r, fmt, media)

    @r.get(
        "/jobs/{job_id}/files/{name}",
        response_class=FileResponse,
        operation_id="get_job_file",
        responses={
            200: {
                "description": "the file: text/markdown for report.md, image/png for a plot, image/svg+xml",
                "content": {
                    media: {"schema": {"type": "string", "format": "binary"}} for media in FILE_MEDIA_TYPES
                },
            }
        }
        | responses(401, 403, 404, 409, 422),
    )
    async def job_file(
        request: Request,
        job_id: JobId,
        name: Annotated[str, Path(max_length=100, description="a name from the job's links.files")],
        _principal: Viewer,
    ) -> FileResponse:
        """A file the job wrote (its links.files): the plots of an identification; a diagnosis's report.md
        and the PNG plots it shows."""
        record = await load_job(request, job_id)
        return await _artefact(record, name, f"job-{job_id}-{name}")

    return r


async def _artefact(record: JobRecord, name: str, download_name: str) -> FileResponse:
    """The artefact `name` of a succeeded job (only names the job recorded: nothing else on disk is
    reachable)."""
    if record.status is not JobStatus.SUCCEEDED:
        raise ApiError(
            409, f"job {record.id} is {record.status.value}; its files exist once it has succeeded"
        )
    if name not in record.artefacts:
        raise ApiError(404, f"job {record.id} has no file {name!r}")
    path = FilePath(record.output_dir) / record.artefacts[name]
    if not await asyncio.to_thread(path.is_file):
        raise ApiError(404, f"the file {name!r} of job {record.id} is no longer on disk")
    media = FILE_MEDIA.get(path.suffix, "application/octet-stream")
    return FileResponse(path, media_type=media, filename=download_name)


def _plot_endpoint(r: APIRouter, fmt: str, media: str) -> None:
    async def plot(request: Request, job_id: JobId, _principal: Viewer) -> FileResponse:
        record = await load_job(request, job_id)
        return await _artefact(record, f"plot.{fmt}", f"job-{job_id}-curve.{fmt}")

    plot.__doc__ = f"The identified curve(s) with their tanh fit, as {fmt.upper()}."
    r.add_api_route(
        f"/jobs/{{job_id}}/plot.{fmt}",
        plot,
        methods=["GET"],
        response_class=FileResponse,
        name=f"job_plot_{fmt}",
        operation_id=f"get_job_plot_{fmt}",
        summary=f"Curve plot ({fmt.upper()})",
        responses=download(media, f"the plot ({media})") | responses(401, 403, 404, 409, 422),
    )


__all__ = ["API_PREFIX", "job_out", "load_job", "router"]
