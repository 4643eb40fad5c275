"""Sweeps on the bench: start one (checked against the safety envelope before anything moves), follow it,
abort it, download its recording as CSV, and run an identification job on it.

A sweep's recording is `sweeps/<id>.h5` in the data directory, its vehicle file `sweeps/<id>.vehicle.toml`
beside it. The sweep runs in the bench's own thread; when it ends, that thread stores the outcome
(complete, or failed/aborted with the reason) through the SweepStore.
"""

from __future__ import annotations

import asyncio
import logging
import os
import secrets
import shutil
import tempfile
from datetime import datetime
from pathlib import Path as FilePath
from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, Query, Request, Response
from fastapi.responses import FileResponse
from pydantic import BaseModel, ConfigDict, Field
from starlette.background import BackgroundTask

from daq.formats.vehicle_file import parse_vehicle
from daq.storage.hdf5_recording import RecordingFileError, RecordingGapError, export_csv
from daq.sweep.model import DEFAULT_SETTLE_S, StopKind, SweepOutcome, SweepRequest
from daq.sweep.run import SweepError
from drivers.exciter.errors import EnvelopeViolationError
from drivers.exciter.sweep import SweepLaw, SweepSettings
from service.access import Principal
from service.api.auth import Operator, Viewer
from service.api.errors import ApiError, responses
from service.api.intake import accept_recording
from service.api.routes.bench import SweepProgressOut, require_bench
from service.api.routes.jobs import job_out
from service.api.schemas import API_PREFIX, JobOut
from service.bench_control import BenchBusyError, BenchController
from service.jobs.identify_job import IdentifyJobOptions
from service.jobs.kinds import KINDS
from service.store.models import JobKind, SweepStatus
from service.store.sweeps import SweepRecord, SweepStore

log = logging.getLogger("shockbench.api")
router = APIRouter(tags=["sweeps"])

SweepId = Annotated[int, Path(ge=1, le=2**62, description="sweep id")]
SETTINGS_FIELDS = ("start_Hz", "stop_Hz", "amplitude_m", "duration_s", "law")


class SweepIn(BaseModel):
    """A sweep to run: the plate's settings, the settling time, and the vehicle on the bench."""

    model_config = ConfigDict(extra="forbid")

    start_Hz: float = Field(0.0, ge=0, le=1000, description="sweep start (Hz)")
    stop_Hz: float = Field(20.0, ge=0, le=1000, description="sweep end (Hz)")
    amplitude_m: float = Field(
        0.004, ge=0, le=1, description="plate amplitude, zero to peak (m); the bench envelope limits it"
    )
    duration_s: float = Field(20.0, gt=0, le=3600, description="the sweep itself, without settling (s)")
    law: SweepLaw = Field(SweepLaw.LINEAR, description="linear or logarithmic")
    settle_s: float = Field(DEFAULT_SETTLE_S, ge=0, le=600, description="recorded after the sweep (s)")
    vehicle_toml: str = Field(
        min_length=1, max_length=1_000_000, description="the vehicle file (TOML, one [vehicle] table)"
    )

    def sweep_settings(self) -> SweepSettings:
        try:
            return SweepSettings(**{name: getattr(self, name) for name in SETTINGS_FIELDS})
        except ValueError as exc:
            field = next((name for name in SETTINGS_FIELDS if name in str(exc)), None)
            raise ApiError(422, str(exc), field=field) from None


class SweepLinks(BaseModel):
    self: str
    abort: str
    recording_csv: str
    jobs: str


class SweepOut(BaseModel):
    id: int
    bench: str
    status: SweepStatus = Field(description="requested, running, complete, failed or aborted")
    settings: dict[str, Any] = Field(description="the sweep settings and settle_s as submitted")
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
    def of(cls, record: SweepRecord, bench: BenchController | None = None) -> SweepOut:
        progress = None
        if bench is not None and not record.finished:
            state = bench.state()
            if state.busy and state.sweep_id == str(record.id):
                progress = SweepProgressOut.of(state.progress)
        base = f"{API_PREFIX}/sweeps/{record.id}"
        return cls(
            id=record.id,
            bench=record.bench,
            status=record.status,
            settings=record.settings,
            complete=record.complete,
            reason=record.reason,
            operator=record.operator,
            recording_file=FilePath(record.recording_path).name if record.recording_path else None,
            progress=progress,
            created_at=record.created_at,
            started_at=record.started_at,
            finished_at=record.finished_at,
            links=SweepLinks(
                self=base, abort=f"{base}/abort", recording_csv=f"{base}/recording.csv", jobs=f"{base}/jobs"
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


# ---- helpers ---------------------------------------------------------------------------------------------


def _store(request: Request) -> SweepStore:
    store: SweepStore = request.app.state.services.sweeps
    return store


async def load_sweep(request: Request, sweep_id: int) -> SweepRecord:
    record = await asyncio.to_thread(_store(request).get, sweep_id)
    if record is None:
        raise ApiError(404, f"no sweep {sweep_id}")
    return record


def sweep_out(request: Request, record: SweepRecord) -> SweepOut:
    return SweepOut.of(record, request.app.state.services.bench)


def outcome_status(outcome: SweepOutcome) -> SweepStatus:
    if outcome.complete:
        return SweepStatus.COMPLETE
    if outcome.stop is StopKind.CONTROLLED and outcome.reason.startswith("aborted"):
        return SweepStatus.ABORTED
    return SweepStatus.FAILED


def sweep_done(store: SweepStore) -> Any:
    """The bench's `done` callback: runs in the sweep's thread and stores how the sweep ended."""

    def done(sweep_id: str, outcome: SweepOutcome | None, error: str) -> None:
        try:
            if outcome is None:
                reason = error or "the sweep did not begin"
                store.finish(int(sweep_id), SweepStatus.FAILED, complete=False, reason=reason)
            else:
                store.finish(
                    int(sweep_id),
                    outcome_status(outcome),
                    complete=outcome.complete,
                    reason=outcome.reason or None,
                )
            log.info("sweep %s ended: %s", sweep_id, outcome.summary() if outcome else error)
        except Exception:  # the sweep thread must not die silently; the row stays for the next restart
            log.exception("could not store the end of sweep %s", sweep_id)

    return done


def _start(
    bench: BenchController, store: SweepStore, data_dir: FilePath, body: SweepIn, principal: Principal
) -> SweepRecord:
    """Check the request (422 naming the field; 409 when busy), store it, start it. Blocking."""
    settings = body.sweep_settings()
    try:
        vehicle = parse_vehicle(body.vehicle_toml, source="vehicle_toml")
    except ValueError as exc:
        raise ApiError(422, str(exc), field="vehicle_toml") from None
    if vehicle.model != bench.config.model:
        raise ApiError(
            422,
            f"vehicle_toml: a {vehicle.model} vehicle cannot be tested on the {bench.config.model} bench",
            field="vehicle_toml",
        )
    try:
        bench.config.safety_envelope().check(settings)
    except EnvelopeViolationError as exc:
        raise ApiError(422, str(exc), field=exc.field) from None
    if bench.busy:
        raise ApiError(409, f"bench {bench.config.name!r} is running a sweep", code="bench_busy")

    folder = data_dir / "sweeps"
    folder.mkdir(parents=True, exist_ok=True)

    def place(sweep_id: int) -> tuple[FilePath, FilePath]:
        recording = folder / f"{sweep_id}.h5"
        if recording.exists():  # a new database over an old data directory: never overwrite
            recording = folder / f"{sweep_id}-{secrets.token_hex(4)}.h5"
        vehicle_file = recording.with_suffix(".vehicle.toml")
        vehicle_file.write_text(body.vehicle_toml, encoding="utf-8")
        return recording, vehicle_file

    as_submitted = {**{name: getattr(body, name) for name in SETTINGS_FIELDS}, "settle_s": body.settle_s}
    record = store.create(
        bench.config.name, {**as_submitted, "law": body.law.value}, place, operator=principal.key_id
    )
    assert record.recording_path is not None and record.vehicle_file is not None
    request = SweepRequest(
        settings,
        vehicle_file=FilePath(record.vehicle_file),
        operator=principal.key_id,
        settle_s=body.settle_s,
    )
    try:
        bench.start_sweep(str(record.id), request, FilePath(record.recording_path), sweep_done(store))
    except BenchBusyError as exc:
        store.finish(record.id, SweepStatus.FAILED, complete=False, reason=str(exc))
        raise ApiError(409, str(exc), code="bench_busy") from None
    except SweepError as exc:
        store.finish(record.id, SweepStatus.FAILED, complete=False, reason=str(exc))
        raise ApiError(422, str(exc)) from None
    store.mark_running(record.id)
    return store.get(record.id) or record


def _recording(record: SweepRecord) -> FilePath:
    if not record.finished:
        raise ApiError(
            409, f"sweep {record.id} is {record.status.value}; its recording is ready once it has ended"
        )
    path = FilePath(record.recording_path) if record.recording_path else None
    if path is None or not path.is_file():
        raise ApiError(404, f"sweep {record.id} has no recording ({record.reason or 'never recorded'})")
    return path


def _export(h5: FilePath, csv: FilePath) -> None:
    try:
        export_csv(h5, csv)
    except RecordingGapError as exc:
        raise ApiError(422, str(exc).replace(str(h5), h5.name), code="recording_gaps") from None
    except RecordingFileError as exc:
        raise ApiError(422, str(exc).replace(str(h5), h5.name), code="bad_recording") from None


def _export_to_temp(record: SweepRecord) -> tuple[FilePath, FilePath]:
    h5 = _recording(record)
    folder = FilePath(tempfile.mkdtemp(prefix=f"sweep-{record.id}-"))
    try:
        csv = folder / f"sweep-{record.id}.csv"
        _export(h5, csv)
        return folder, csv
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise


def _sweep_csv(record: SweepRecord) -> FilePath:
    """The recording as CSV beside the HDF5 file (exported once; a finished recording never changes)."""
    h5 = _recording(record)
    csv = h5.with_suffix(".csv")
    if not csv.is_file():
        partial = csv.with_name(f".{csv.name}.{secrets.token_hex(4)}.part")
        try:
            _export(h5, partial)
            os.replace(partial, csv)
        finally:
            partial.unlink(missing_ok=True)
    return csv


# ---- routes ----------------------------------------------------------------------------------------------


@router.post(
    "/sweeps",
    status_code=201,
    response_model=SweepOut,
    responses=responses(400, 401, 403, 409, 422, 503),
)
async def start_sweep(request: Request, response: Response, body: SweepIn, principal: Operator) -> SweepOut:
    """Start a sweep. Checked before anything moves: the settings (422 naming the field, e.g.
    amplitude_m above the bench's safety envelope), the vehicle file (422, field vehicle_toml); 409 while
    the bench runs another sweep. Answers 201 with Location: the sweep, to poll."""
    bench = require_bench(request)
    services = request.app.state.services
    data_dir = services.settings.data_dir
    record = await asyncio.to_thread(_start, bench, services.sweeps, data_dir, body, principal)
    out = sweep_out(request, record)
    response.headers["Location"] = out.links.self
    return out


@router.get("/sweeps", response_model=SweepList, responses=responses(401, 403, 422))
async def list_sweeps(
    request: Request,
    _principal: Viewer,
    status: SweepStatus | None = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=2**31)] = 0,
) -> SweepList:
    """Sweeps, newest first."""
    records, total = await asyncio.to_thread(
        _store(request).list_sweeps, status=status, limit=limit, offset=offset
    )
    return SweepList(sweeps=[sweep_out(request, r) for r in records], total=total, limit=limit, offset=offset)


@router.get("/sweeps/{sweep_id}", response_model=SweepOut, responses=responses(401, 403, 404, 422))
async def get_sweep(request: Request, sweep_id: SweepId, _principal: Viewer) -> SweepOut:
    """Status (with live progress while it runs), settings, and why it failed or was aborted."""
    return sweep_out(request, await load_sweep(request, sweep_id))


@router.post(
    "/sweeps/{sweep_id}/abort",
    status_code=202,
    response_model=SweepOut,
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
    return sweep_out(request, record)


@router.get(
    "/sweeps/{sweep_id}/recording.csv",
    response_class=FileResponse,
    responses={200: {"content": {"text/csv": {}}, "description": "the recording CSV"}}
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


@router.post(
    "/sweeps/{sweep_id}/jobs",
    status_code=201,
    response_model=JobOut,
    responses=responses(400, 401, 403, 404, 409, 422),
)
async def identify_sweep(
    request: Request,
    response: Response,
    sweep_id: SweepId,
    principal: Operator,
    options: Annotated[SweepJobIn | None, Body()] = None,
) -> JobOut:
    """An identification job on the sweep's recording (JSON body: the options of POST /jobs, all
    optional). 409 until the sweep has ended. Answers 201 with Location: the job."""
    services = request.app.state.services
    record = await load_sweep(request, sweep_id)
    job_options = IdentifyJobOptions.model_validate((options or SweepJobIn()).model_dump())

    def accept() -> Any:
        csv = _sweep_csv(record)
        assert record.vehicle_file is not None
        return accept_recording(
            services.settings,
            services.jobs,
            KINDS[JobKind.IDENTIFY.value],
            job_options,
            csv,
            FilePath(record.vehicle_file),
            principal,
            sweep_id=record.id,
        )

    job = await asyncio.to_thread(accept)
    services.manager.enqueue(job)
    out = job_out(request, job)
    response.headers["Location"] = out.links.self
    return out
