"""Scheduled inspection-line tests: submit one (admin; checked now exactly as a sweep is, 422 naming the
field), list them, follow one to its sweep and identification job, cancel one that has not begun.

The vehicle file of a test is saved as `schedules/<id>.vehicle.toml` in the data directory; the scheduler
(service.api.scheduler) runs the tests one at a time on the bench.
"""

from __future__ import annotations

import asyncio
import secrets
from datetime import datetime
from pathlib import Path as FilePath
from typing import Annotated

from fastapi import APIRouter, Path, Query, Request, Response
from pydantic import AwareDatetime, BaseModel, ConfigDict, Field

from service.access import Principal
from service.api.auth import Admin, Viewer
from service.api.contract import created
from service.api.errors import ApiError, responses
from service.api.quotas import QUOTA_RESPONSES, schedule_quota
from service.api.routes.bench import require_bench
from service.api.routes.sweeps import SweepTestOut
from service.api.schemas import API_PREFIX, IdentifyOptionsOut, PageLimit, PageOffset, SweepSettingsOut
from service.api.settings import ServiceSettings
from service.api.sweep_launch import SweepIn, plan_request
from service.bench_control import BenchController
from service.jobs.identify_job import IdentifyJobOptions
from service.store.models import ScheduleStatus
from service.store.schedules import ScheduleRecord, ScheduleStore

router = APIRouter(tags=["schedules"])

TestId = Annotated[int, Path(ge=1, le=2**62, description="scheduled test id")]


class JobOptionsIn(IdentifyJobOptions):
    model_config = ConfigDict(extra="forbid")


class ScheduleIn(SweepIn):
    """A test for the inspection line: the sweep (as for POST /sweeps), when to run it, and the options of
    the identification job run on its recording."""

    run_at: AwareDatetime | None = Field(
        None,
        description="when to run it (ISO 8601 with a zone, e.g. 2026-11-23T06:30:00+01:00); omitted: as soon "
        "as the bench is free. A test whose time has passed runs at the next free moment.",
    )
    job: JobOptionsIn = Field(
        default_factory=JobOptionsIn, description="options of the identification job (as for POST /jobs)"
    )


class ScheduleLinks(BaseModel):
    self: str
    cancel: str
    sweep: str | None = None
    job: str | None = None


class ScheduleOut(BaseModel):
    id: int
    lane: str = Field(description="the lane whose scheduler runs it")
    bench: str
    status: ScheduleStatus = Field(description="waiting, running, done, failed or cancelled")
    run_at: datetime | None = Field(None, description="when it is due; null: when the bench is free")
    sweep_settings: SweepSettingsOut = Field(description="the sweep as submitted (without the vehicle file)")
    test: SweepTestOut = Field(description="the vehicle id, tyre pressure and operator its sweep will carry")
    job_options: IdentifyOptionsOut = Field(description="options of the identification job")  # type: ignore[valid-type]
    sweep_id: int | None = Field(None, description="its sweep, once started")
    job_id: int | None = Field(None, description="its identification job, once the sweep completed")
    reason: str | None = Field(None, description="why it failed or was cancelled")
    created_by: str | None = Field(None, description="id of the key that scheduled it (a hash)")
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    links: ScheduleLinks

    @classmethod
    def of(cls, record: ScheduleRecord) -> ScheduleOut:
        base = f"{API_PREFIX}/schedules/{record.id}"
        return cls(
            id=record.id,
            lane=record.lane,
            bench=record.bench,
            status=record.status,
            run_at=record.run_at,
            sweep_settings=SweepSettingsOut.model_validate(record.sweep_settings),
            test=SweepTestOut.model_validate(record.sweep_settings),
            job_options=IdentifyOptionsOut.model_validate(record.job_options),
            sweep_id=record.sweep_id,
            job_id=record.job_id,
            reason=record.reason,
            created_by=record.created_by,
            created_at=record.created_at,
            started_at=record.started_at,
            finished_at=record.finished_at,
            links=ScheduleLinks(
                self=base,
                cancel=f"{base}/cancel",
                sweep=f"{API_PREFIX}/sweeps/{record.sweep_id}" if record.sweep_id else None,
                job=f"{API_PREFIX}/jobs/{record.job_id}" if record.job_id else None,
            ),
        )


class ScheduleList(BaseModel):
    tests: list[ScheduleOut] = Field(description="newest first")
    total: int
    limit: int
    offset: int


def _store(request: Request) -> ScheduleStore:
    store: ScheduleStore = request.app.state.services.tests
    return store


async def _load(request: Request, test_id: int) -> ScheduleRecord:
    record = await asyncio.to_thread(_store(request).get, test_id)
    if record is None:
        raise ApiError(404, f"no scheduled test {test_id}")
    return record


def _create(
    bench: BenchController,
    store: ScheduleStore,
    settings: ServiceSettings,
    body: ScheduleIn,
    principal: Principal,
) -> ScheduleRecord:
    """Check as a sweep is checked (422 naming the field), then store the test. Blocking."""
    vehicle = plan_request(bench, body).request.vehicle
    assert vehicle is not None  # a scheduled test's request always names its vehicle
    model = vehicle.parameters.model
    if body.job.model is not None and body.job.model is not model:
        raise ApiError(
            422,
            f"job.model is {body.job.model.value} but the vehicle file says {model.value}",
            field="job.model",
        )
    folder = settings.data_dir / "schedules"
    folder.mkdir(parents=True, exist_ok=True)

    def place(test_id: int) -> FilePath:
        path = folder / f"{test_id}.vehicle.toml"
        if path.exists():  # a new database over an old data directory: never overwrite
            path = folder / f"{test_id}-{secrets.token_hex(4)}.vehicle.toml"
        path.write_text(body.vehicle_toml, encoding="utf-8")
        return path

    return store.create(
        bench.config.name,
        body.as_submitted(),
        body.job.model_dump(mode="json"),
        body.run_at,
        place,
        created_by=principal.key_id,
        quota=schedule_quota(settings, principal),
    )


@router.post(
    "/schedules",
    status_code=201,
    response_model=ScheduleOut,
    operation_id="schedule_test",
    responses=created("scheduled test") | responses(400, 401, 403, 422, 503) | QUOTA_RESPONSES,
)
async def schedule_test(
    request: Request, response: Response, body: ScheduleIn, principal: Admin
) -> ScheduleOut:
    """Schedule an inspection-line test (admin). Checked now as a sweep is (422 naming the field: the bench's
    safety envelope, the vehicle file); it then waits for its time, or for the bench to be free, and runs
    one at a time with the bench's other tests. Answers 201 with Location: the test, to poll. 429
    (Retry-After) when the key has as many tests waiting or running as allowed."""
    bench = require_bench(request)
    services = request.app.state.services
    record = await asyncio.to_thread(_create, bench, _store(request), services.settings, body, principal)
    services.wake_scheduler()
    out = ScheduleOut.of(record)
    response.headers["Location"] = out.links.self
    return out


@router.get(
    "/schedules",
    response_model=ScheduleList,
    operation_id="list_scheduled_tests",
    responses=responses(401, 403, 422),
)
async def list_tests(
    request: Request,
    _principal: Viewer,
    status: ScheduleStatus | None = None,
    lane: Annotated[str | None, Query(max_length=100, description="only this lane's")] = None,
    limit: PageLimit = 50,
    offset: PageOffset = 0,
) -> ScheduleList:
    """Scheduled tests, newest first (of every lane, or of `lane`)."""
    records, total = await asyncio.to_thread(
        _store(request).list_tests, status=status, lane=lane, limit=limit, offset=offset
    )
    return ScheduleList(tests=[ScheduleOut.of(r) for r in records], total=total, limit=limit, offset=offset)


@router.get(
    "/schedules/{test_id}",
    response_model=ScheduleOut,
    operation_id="get_scheduled_test",
    responses=responses(401, 403, 404, 422),
)
async def get_test(request: Request, test_id: TestId, _principal: Viewer) -> ScheduleOut:
    """A scheduled test: waiting, running (its sweep), done (its sweep and its identification job), failed
    (why) or cancelled."""
    return ScheduleOut.of(await _load(request, test_id))


@router.post(
    "/schedules/{test_id}/cancel",
    response_model=ScheduleOut,
    operation_id="cancel_scheduled_test",
    responses=responses(401, 403, 404, 409, 422),
)
async def cancel_test(request: Request, test_id: TestId, _principal: Admin) -> ScheduleOut:
    """Cancel a test that has not begun (admin). 409 once it runs (abort its sweep instead) or has ended."""
    store = _store(request)
    record = await _load(request, test_id)
    if not await asyncio.to_thread(store.cancel, test_id):
        now = await asyncio.to_thread(store.get, test_id) or record
        hint = (
            f"; abort sweep {now.sweep_id} to stop it"
            if now.status is ScheduleStatus.RUNNING and now.sweep_id
            else ""
        )
        raise ApiError(409, f"scheduled test {test_id} is {now.status.value}{hint}")
    return ScheduleOut.of(await _load(request, test_id))
