"""Request bodies: the size caps (BodySizeLimit) and the deadlines (BodyDeadline).

The size caps: a request body larger than its route's cap is refused with 413 and a clear message, before
it is stored anywhere. The routes that take a multipart upload (a recording CSV: POST /jobs, /diagnoses,
/validations) have the upload limit (64 MiB by default); every other route takes JSON, whose largest
field is the vehicle text (at most 1,000,000 characters), and has the JSON limit (1 MiB + 64 KiB by
default: the text, its escaping and the other fields). Which route a request is for, the key gate
(service.api.key_gate) has found already. A declared Content-Length over the cap is refused before the
body is read; a body without one (chunked) is counted as it arrives, and once past the cap, reading it
raises BodyTooLarge, an HTTPException that FastAPI passes through its parsing unchanged and the error
handlers render as 413.

What parsing is left on the event loop, and why it stays short (measured on the 2-core development
machine, Python 3.11): FastAPI parses a JSON body (json.loads and the pydantic model) on the loop; at the
JSON cap (1.1 MB, a 1,000,000-character vehicle text) that takes about 4 ms, once per request. Reading the
TOML inside it happens in a thread (the sweep and schedule routes). A multipart upload is parsed by
python-multipart as its chunks arrive: about 0.2 s of work for 40 MB, spread over the chunks uvicorn
hands over (at most a few hundred KiB each, about 0.5 ms of parsing each, even for bodies made of
near-boundaries), with the file parts written to disk in threads; the recording itself is read and
checked in the input checker's process (service.api.input_check). Neither holds the loop for long at a
time; benchmarks/bench_hostile_clients.py measures GET /status and the emergency stop beside them.

The deadlines: uvicorn times out an idle keep-alive connection, and the connection guard
(service.api.connection_limits) the request headers; nothing timed a body. Reading the body must keep
to three limits, each answered 408 with `Connection: close`:
- a pause: each read must bring something within `pause_s` (a client that declared more than it sends);
- a minimum rate: after a grace period, the body must have arrived at `min_rate_bytes_s` on average
  since the request began (a trickle of 1 byte every 2 s used to be held for as long as it lasted);
- a total: the whole body within `total_s`.
And a response that starts before an announced body has been read to its end (a 404, a 405, a 413, an
error raised before the body was needed) carries `Connection: close`: uvicorn would otherwise read and
discard the rest of the body, however long, to keep the connection.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass

from fastapi import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.errors import error_response
from service.api.key_gate import OPEN, POLICY_SCOPE_KEY, RoutePolicy, announces_body, declared_length

CLOSE = {"Connection": "close"}


def too_large_message(limit: int, what: str = "upload") -> str:
    return f"request body larger than the {what} limit of {limit / 2**20:.3g} MiB ({limit} bytes)"


class BodyTooLarge(HTTPException):
    def __init__(self, limit: int, what: str = "upload") -> None:
        super().__init__(413, too_large_message(limit, what), headers=CLOSE)


class BodySizeLimit:
    """Pure ASGI middleware (no buffering, streaming responses unaffected): `max_upload_bytes` for the
    multipart upload routes, `max_json_bytes` for every other route."""

    def __init__(self, app: ASGIApp, max_upload_bytes: int, max_json_bytes: int) -> None:
        self.app = app
        self.max_upload_bytes = max_upload_bytes
        self.max_json_bytes = max_json_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        policy: RoutePolicy = scope.get(POLICY_SCOPE_KEY, OPEN)
        limit, what = (
            (self.max_upload_bytes, "upload") if policy.upload else (self.max_json_bytes, "JSON body")
        )
        length = declared_length(scope)
        if length is not None:
            if length < 0:
                await error_response(400, "bad_request", "invalid Content-Length header", headers=CLOSE)(
                    scope, receive, send
                )
                return
            if length > limit:
                message = too_large_message(limit, what)
                await error_response(413, "payload_too_large", message, headers=CLOSE)(scope, receive, send)
                return
        received = 0

        async def counted() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise BodyTooLarge(limit, what)
            return message

        await self.app(scope, counted, send)


class BodyTooSlow(HTTPException):
    """408: the body broke one of BodyDeadline's limits; the message says which."""

    def __init__(self, message: str) -> None:
        super().__init__(408, message, headers=CLOSE)


@dataclass(frozen=True)
class BodyDeadlines:
    pause_s: float
    """Longest wait for the next piece of the body."""
    min_rate_bytes_s: float
    """Least average rate (bytes/s) since the request began, once `grace_s` has passed (0: none)."""
    grace_s: float
    total_s: float
    """Longest time for the whole body."""


class BodyDeadline:
    """Pure ASGI middleware: reading the body raises BodyTooSlow (an HTTPException the error handlers
    render, with `Connection: close`) when it breaks a limit of `deadlines`; a response that starts
    before an announced body was read to its end gets `Connection: close`. A request without a body is
    passed through untouched (an event stream's wait for the client's disconnect is no body read).
    `clock` is injectable for tests."""

    def __init__(
        self, app: ASGIApp, deadlines: BodyDeadlines, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.app = app
        self.deadlines = deadlines
        self.clock = clock

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not announces_body(scope):
            await self.app(scope, receive, send)
            return
        limits = self.deadlines
        started = self.clock()
        received = 0
        body_done = False

        def next_deadline() -> tuple[float, str]:
            """The moment the body breaks a limit unless more arrives, and which limit that is."""
            candidates = [(started + limits.total_s, "total")]
            if limits.min_rate_bytes_s > 0:
                candidates.append((started + limits.grace_s + received / limits.min_rate_bytes_s, "rate"))
            return min(candidates)

        def broken(limit: str) -> BodyTooSlow:
            if limit == "pause":
                return BodyTooSlow(
                    f"the request body stopped arriving: nothing for {limits.pause_s:g} s before it was "
                    "complete"
                )
            if limit == "total":
                return BodyTooSlow(
                    f"the request body took longer than the {limits.total_s:g} s allowed for a whole body"
                )
            return BodyTooSlow(
                f"the request body arrived too slowly: {received} bytes in {self.clock() - started:.3g} s, "
                f"under the minimum of {limits.min_rate_bytes_s:g} bytes/s after the first "
                f"{limits.grace_s:g} s"
            )

        async def timed() -> Message:
            nonlocal body_done, received
            if body_done:  # after the body only a disconnect can come: waiting for it is no body read
                return await receive()
            now = self.clock()
            deadline, limit = min(next_deadline(), (now + limits.pause_s, "pause"))
            if deadline <= now:
                raise broken(limit)
            try:
                event = await asyncio.wait_for(receive(), deadline - now)
            except TimeoutError:
                raise broken(limit) from None
            if event["type"] == "http.request":
                received += len(event.get("body", b""))
            if event["type"] != "http.request" or not event.get("more_body", False):
                body_done = True
            return event

        async def closing_early(event: Message) -> None:
            if event["type"] == "http.response.start" and not body_done:
                headers = list(event.get("headers", []))
                if not any(name.lower() == b"connection" for name, _ in headers):
                    event = {**event, "headers": [*headers, (b"connection", b"close")]}
            await send(event)

        await self.app(scope, timed, closing_early)
