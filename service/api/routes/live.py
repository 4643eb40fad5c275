"""GET /api/v1/bench/live: the bench as the operator page watches it, as Server-Sent Events.

`state` (busy, the running sweep, its progress) comes first, whenever the phase or the sweep changes, and
at least once a second; `samples` carries the rows recorded since the last event, decimated to about 100
per second of signal (daq.live_view), about 20 times a second while a sweep records. The stream reads
the bench controller's LiveView with its own cursor: any number of screens cost the acquisition nothing
but the view's one decimated copy. When the service stops, the stream ends with `closing`.

EventSource cannot send an Authorization header: a page reads this stream with fetch and a
ReadableStream (service/web/app.js).

The events are encoded by FastAPI (fastapi.sse: `response_class=EventSourceResponse` on a generator); the
checks that may refuse the stream (503 without a bench, 429) run in a dependency, before the response
starts.
"""

from __future__ import annotations

import asyncio
import itertools
import math
import time
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Depends, Request
from fastapi.sse import EventSourceResponse, ServerSentEvent
from pydantic import BaseModel

from daq.live_view import LiveRows
from service.api.auth import Viewer
from service.api.contract import event_stream, stream_errors
from service.api.routes.bench import bench_out, require_bench
from service.api.schemas import LIVE_EVENTS, LiveClosingEvent, LiveSamplesEvent, LiveStateEvent
from service.bench_control import BenchController

TICK_S = 0.05
"""Time between two looks at the bench: up to 20 `samples` events a second."""
STATE_EVERY_S = 1.0
"""A `state` event at least this often, changed or not (a screen shows the stream is alive)."""
DECIMALS = 7
"""Displacements sent to 0.1 µm: enough for a chart, a third of the text of full floats."""

LIVE_SUMMARY = (
    "Server-Sent Events, each `id: N`, `event: NAME`, `data: JSON`: the bench's state and, while a sweep "
    "records, its plate, wheel and body channels decimated for a live chart. Runs until the client closes "
    "it (or `closing`)."
)

router = APIRouter(tags=["bench"])


def _rounded(values: list[float]) -> list[float | None]:
    return [round(v, DECIMALS) if math.isfinite(v) else None for v in values]


def samples_event(rows: LiveRows) -> LiveSamplesEvent:
    return LiveSamplesEvent(
        sweep_id=int(rows.label) if rows.label.isdigit() else None,
        t_s=[round(t, 4) for t in rows.time_s.tolist()],
        channels={name: _rounded(values.tolist()) for name, values in rows.channels.items()},
        missed=rows.missed,
    )


async def open_live_stream(request: Request, principal: Viewer) -> AsyncIterator[BenchController]:
    """503 without a bench, 429 when the key has its most streams open; both before the response starts.
    The place is given back once the stream ended, however it ended."""
    bench = require_bench(request)
    with request.app.state.services.streams.held(principal.key_id):
        yield bench


@router.get(
    "/bench/live",
    response_class=EventSourceResponse,
    operation_id="bench_live",
    responses=event_stream(LIVE_EVENTS, LIVE_SUMMARY) | stream_errors(401, 403, 429, 503),
)
async def bench_live(
    bench: Annotated[BenchController, Depends(open_live_stream)],
) -> AsyncIterator[ServerSentEvent]:
    """The bench's state and the running sweep's channels, live (see the module text for the events)."""
    numbers = itertools.count(1)

    def event(name: str, data: BaseModel) -> ServerSentEvent:
        return ServerSentEvent(event=name, data=data, id=str(next(numbers)))

    cursor, run = 0, None
    last_phase: tuple[int | None, str | None] | None = None
    last_sent = -math.inf
    while True:
        if bench.stopping:
            yield event("closing", LiveClosingEvent(reason="the service is stopping"))
            return
        state = bench_out(bench)
        phase = (state.sweep_id, state.progress.phase if state.progress else None)
        now = time.monotonic()
        if phase != last_phase or now - last_sent >= STATE_EVERY_S:
            # built only when sent: the devices' states cost a lock and a pass over their statistics
            data = LiveStateEvent(
                busy=state.busy, sweep_id=state.sweep_id, progress=state.progress, devices=bench.devices()
            )
            yield event("state", data)
            last_phase, last_sent = phase, now
        rows = bench.live.since(cursor, run)
        cursor, run = rows.cursor, rows.run
        if rows.time_s.size or rows.missed:
            yield event("samples", samples_event(rows))
        await asyncio.sleep(TICK_S)
