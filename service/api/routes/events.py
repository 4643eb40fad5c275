"""GET /api/v1/jobs/{id}/events: a job's progress as Server-Sent Events.

The stream opens with `state` (the job as GET returns it), then `progress` events (stage, generation,
best objective, ETA) while the job runs, and a `state` event when it starts; it ends with exactly one
final event named for the outcome, `succeeded`, `failed` or `cancelled`, whose data is the job with its
result or reason. A comment line every 15 s keeps proxies from closing a quiet stream. For a job already
finished the stream is `state` then the final event. When the service stops, open streams end with a
`closing` event (reconnect, or poll). Polling GET /jobs/{id} gives the same information.

Any instance answers for any job: a job another instance runs (the shared queue) has no events here, so
while the stream waits it reads the job from the database every POLL_S and sends what changed there (its
start, its progress as persisted, its end).
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Annotated, Any

from fastapi import APIRouter, Path, Request
from fastapi.responses import StreamingResponse

from service.api.auth import Viewer
from service.api.contract import event_stream
from service.api.errors import ApiError, responses
from service.api.routes.jobs import job_out
from service.api.schemas import ProgressOut
from service.api.stream_limit import HeldStreamingResponse
from service.jobs.broker import JobEvent
from service.jobs.messages import Progress

KEEPALIVE_S = 15.0
POLL_S = 1.0
"""While no event comes, the job is read from the database this often (it may run on another instance)."""

router = APIRouter(tags=["jobs"])


def sse(event: str, data: dict, event_id: int) -> str:
    return f"id: {event_id}\nevent: {event}\ndata: {json.dumps(data, separators=(',', ':'))}\n\n"


def progress_data(job_id: int, progress: Progress | dict[str, Any]) -> dict[str, Any]:
    """The data of a `progress` event (ProgressEvent), from the live progress or the one persisted."""
    out = ProgressOut.of(progress)
    return {"job_id": job_id, **(out.model_dump(mode="json") if out else {})}


@router.get(
    "/jobs/{job_id}/events",
    response_class=StreamingResponse,
    operation_id="job_events",
    responses=event_stream() | responses(401, 403, 404, 422, 429),
)
async def job_events(
    request: Request, job_id: Annotated[int, Path(ge=1, le=2**62)], principal: Viewer
) -> StreamingResponse:
    """Progress and outcome of a job as Server-Sent Events (see the module text for the event names)."""
    services = request.app.state.services
    streams = services.streams
    streams.acquire(principal.key_id)  # 429 when this key has its most streams open
    queue = services.manager.broker.subscribe(job_id)  # before reading: no event can fall in between
    try:
        record = await asyncio.to_thread(services.jobs.get, job_id)
        if record is None:
            raise ApiError(404, f"no job {job_id}")
    except BaseException:
        services.manager.broker.unsubscribe(job_id, queue)
        streams.release(principal.key_id)
        raise

    async def stream() -> AsyncIterator[str]:
        sequence = 0

        def next_id() -> int:
            nonlocal sequence
            sequence += 1
            return sequence

        try:
            yield sse("state", job_out(request, record).model_dump(mode="json"), next_id())
            if record.status.finished:
                yield sse(record.status.value, job_out(request, record).model_dump(mode="json"), next_id())
                return
            seen, quiet_s = record, 0.0
            while True:
                try:
                    event: JobEvent = await asyncio.wait_for(queue.get(), POLL_S)
                except TimeoutError:
                    quiet_s += POLL_S
                    # a job this instance runs has its events come through the broker; another's is read
                    now = (
                        None
                        if services.manager.runs_here(job_id)
                        else await asyncio.to_thread(services.jobs.get, job_id)
                    )
                    if now is not None and now.status.finished:
                        yield sse(now.status.value, job_out(request, now).model_dump(mode="json"), next_id())
                        return
                    if now is not None and now.status != seen.status:
                        yield sse("state", job_out(request, now).model_dump(mode="json"), next_id())
                        seen, quiet_s = now, 0.0
                    elif now is not None and now.progress and now.progress != seen.progress:
                        yield sse("progress", progress_data(job_id, now.progress), next_id())
                        seen, quiet_s = now, 0.0
                    if quiet_s >= KEEPALIVE_S:
                        yield ": keep-alive\n\n"
                        quiet_s = 0.0
                    continue
                if event.name == "closing":
                    yield sse("closing", {"job_id": job_id, "reason": "the service is stopping"}, next_id())
                    return
                if event.name == "progress" and event.progress is not None:
                    yield sse("progress", progress_data(job_id, event.progress), next_id())
                elif event.record is not None:
                    out = job_out(request, event.record).model_dump(mode="json")
                    if event.name == "finished":
                        yield sse(event.record.status.value, out, next_id())
                        return
                    yield sse("state", out, next_id())
        finally:
            services.manager.broker.unsubscribe(job_id, queue)

    return HeldStreamingResponse(
        stream(),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
        on_close=lambda: streams.release(principal.key_id),
    )
