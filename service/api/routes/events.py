"""GET /api/v1/jobs/{id}/events: a job's progress as Server-Sent Events.

The stream opens with `state` (the job as GET returns it), then `progress` events (stage, generation,
best objective, ETA) while the job runs, and a `state` event when it starts; it ends with exactly one
final event named for the outcome, `succeeded`, `failed` or `cancelled`, whose data is the job with its
result or reason. A comment line every 15 s keeps proxies from closing a quiet stream (FastAPI's
EventSourceResponse sends it). For a job already finished the stream is `state` then the final event.
When the service stops, open streams end with a `closing` event (reconnect, or poll). Polling
GET /jobs/{id} gives the same information.

Any instance answers for any job: a job another instance runs (the shared queue) has no events here, so
while the stream waits it reads the job from the database every POLL_S and sends what changed there (its
start, its progress as persisted, its end).

The events are encoded by FastAPI (fastapi.sse: `response_class=EventSourceResponse` on a generator); the
checks that may refuse the stream (429, 404) run in a dependency, before the response starts.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path, Request
from fastapi.sse import EventSourceResponse, ServerSentEvent
from pydantic import BaseModel

from service.api.auth import Viewer
from service.api.contract import event_stream, stream_errors
from service.api.errors import ApiError
from service.api.routes.jobs import job_out
from service.api.schemas import ClosingEvent, ProgressEvent, ProgressOut
from service.jobs.broker import JobClosingEvent, JobEvent, JobFinishedEvent, JobProgressEvent, JobStateEvent
from service.jobs.messages import Progress
from service.store.jobs import JobRecord

POLL_S = 1.0
"""While no event comes, the job is read from the database this often (it may run on another instance)."""
CLOSING_REASON = "the service is stopping"

router = APIRouter(tags=["jobs"])


def progress_data(job_id: int, progress: Progress | dict[str, Any]) -> ProgressEvent:
    """The data of a `progress` event, from the live progress or the one persisted."""
    out = ProgressOut.of(progress)
    assert out is not None
    return ProgressEvent(job_id=job_id, **out.model_dump())


@dataclass
class JobStream:
    """A stream's place under its key's limit, its subscription to the job's events, and the job as it
    was when the stream opened (subscribed first: no event can fall in between)."""

    job_id: int
    record: JobRecord
    queue: asyncio.Queue[JobEvent]


async def open_job_stream(
    request: Request, job_id: Annotated[int, Path(ge=1, le=2**62)], principal: Viewer
) -> AsyncIterator[JobStream]:
    """429 when the key has its most streams open, 404 for no such job; both before the response starts.
    The place and the subscription are given back once the stream ended, however it ended."""
    services = request.app.state.services
    broker = services.manager.broker
    with services.streams.held(principal.key_id):
        queue = broker.subscribe(job_id)
        try:
            record = await asyncio.to_thread(services.jobs.get, job_id)
            if record is None:
                raise ApiError(404, f"no job {job_id}")
            yield JobStream(job_id, record, queue)
        finally:
            broker.unsubscribe(job_id, queue)


@router.get(
    "/jobs/{job_id}/events",
    response_class=EventSourceResponse,
    operation_id="job_events",
    responses=event_stream() | stream_errors(401, 403, 404, 422, 429),
)
async def job_events(
    request: Request, opened: Annotated[JobStream, Depends(open_job_stream)]
) -> AsyncIterator[ServerSentEvent]:
    """Progress and outcome of a job as Server-Sent Events (see the module text for the event names)."""
    services = request.app.state.services
    job_id, record, queue = opened.job_id, opened.record, opened.queue
    numbers = itertools.count(1)

    def event(name: str, data: BaseModel) -> ServerSentEvent:
        return ServerSentEvent(event=name, data=data, id=str(next(numbers)))

    def job(now: JobRecord) -> BaseModel:
        return job_out(request, now)

    yield event("state", job(record))
    if record.status.finished:
        yield event(record.status.value, job(record))
        return
    seen = record
    while True:
        try:
            message = await asyncio.wait_for(queue.get(), POLL_S)
        except TimeoutError:
            # a job this instance runs has its events come through the broker; another's is read
            if services.manager.runs_here(job_id):
                continue
            now = await asyncio.to_thread(services.jobs.get, job_id)
            if now is None:
                continue
            if now.status.finished:
                yield event(now.status.value, job(now))
                return
            if now.status != seen.status:
                yield event("state", job(now))
                seen = now
            elif now.progress and now.progress != seen.progress:
                yield event("progress", progress_data(job_id, now.progress))
                seen = now
            continue
        match message:
            case JobClosingEvent():
                yield event("closing", ClosingEvent(job_id=job_id, reason=CLOSING_REASON))
                return
            case JobProgressEvent(progress=progress):
                yield event("progress", progress_data(job_id, progress))
            case JobFinishedEvent(record=final):
                yield event(final.status.value, job(final))
                return
            case JobStateEvent(record=changed):
                yield event("state", job(changed))
