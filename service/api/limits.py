"""Request bodies: the size limit (UploadSizeLimit) and the read timeout (BodyTimeout).

The upload size limit: a request body larger than the limit is refused with 413 and a clear message,
before it is stored anywhere.

A declared Content-Length over the limit is refused before the body is read. A body without one
(chunked) is counted as it arrives; once past the limit, reading it raises BodyTooLarge, an HTTPException
that FastAPI passes through its form parsing unchanged and the error handlers render as 413.
"""

from __future__ import annotations

import asyncio

from fastapi import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.errors import error_response


def too_large_message(limit: int) -> str:
    return f"request body larger than the upload limit of {limit / 2**20:.3g} MiB ({limit} bytes)"


class BodyTooLarge(HTTPException):
    def __init__(self, limit: int) -> None:
        super().__init__(413, too_large_message(limit))


class UploadSizeLimit:
    """Pure ASGI middleware (no buffering, streaming responses unaffected)."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None:
            try:
                length = int(declared)
            except ValueError:
                length = -1
            if length < 0:
                await error_response(400, "bad_request", "invalid Content-Length header")(
                    scope, receive, send
                )
                return
            if length > self.max_bytes:
                response = error_response(413, "payload_too_large", too_large_message(self.max_bytes))
                await response(scope, receive, send)
                return
        received = 0

        async def counted() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    raise BodyTooLarge(self.max_bytes)
            return message

        await self.app(scope, counted, send)


class BodyReadTimeout(HTTPException):
    def __init__(self, timeout_s: float) -> None:
        super().__init__(
            408,
            f"the request body stopped arriving: nothing for {timeout_s:g} s before it was complete",
            headers={"Connection": "close"},
        )


class BodyTimeout:
    """A server-side timeout for request bodies (uvicorn has one for idle keep-alive connections, none for a
    body that stops arriving): each read of the body must bring something within `timeout_s`, or the
    request is answered 408 with `Connection: close` and the connection freed. A slow upload that keeps
    arriving is never cut; a client that declared more than it sends is. Pure ASGI middleware: reading the
    body raises BodyReadTimeout, an HTTPException the error handlers render (as for BodyTooLarge)."""

    def __init__(self, app: ASGIApp, timeout_s: float) -> None:
        self.app = app
        self.timeout_s = timeout_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        body_done = False

        async def timed() -> Message:
            nonlocal body_done
            if body_done:  # after the body only a disconnect can come: waiting for it is no body read
                return await receive()
            try:
                message = await asyncio.wait_for(receive(), self.timeout_s)
            except TimeoutError:
                raise BodyReadTimeout(self.timeout_s) from None
            if message["type"] != "http.request" or not message.get("more_body", False):
                body_done = True
            return message

        await self.app(scope, timed, send)
