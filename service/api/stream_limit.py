"""At most N open event streams per key (`serve --max-streams-per-key`).

An event stream holds a connection and a queue in the service for as long as its job runs; a client that
opens streams in a loop (a dashboard reloading, a script without a `with`) would hold them all. Each key
may have `limit` streams open at once; one more is refused with 429 and a Retry-After, until one ends.
Everything runs on the event loop: a counter per key, no lock needed.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

from fastapi.responses import StreamingResponse
from starlette.types import Receive, Scope, Send

from service.api.errors import ApiError

DEFAULT_MAX_STREAMS_PER_KEY = 8
RETRY_AFTER_S = 5


class StreamLimit:
    def __init__(self, limit: int = DEFAULT_MAX_STREAMS_PER_KEY) -> None:
        if limit < 1:
            raise ValueError("the stream limit per key must be at least 1")
        self.limit = limit
        self._open: Counter[str] = Counter()

    def open_count(self, key_id: str) -> int:
        return self._open[key_id]

    def acquire(self, key_id: str) -> None:
        """Count one more stream of `key_id`, or ApiError 429 when it has `limit` open."""
        if self._open[key_id] >= self.limit:
            raise ApiError(
                429,
                f"this key has {self._open[key_id]} event streams open, the most allowed; close one, or "
                "poll GET /jobs/{id}",
                headers={"Retry-After": str(RETRY_AFTER_S)},
            )
        self._open[key_id] += 1

    def release(self, key_id: str) -> None:
        self._open[key_id] -= 1
        if self._open[key_id] <= 0:
            del self._open[key_id]


class HeldStreamingResponse(StreamingResponse):
    """A StreamingResponse that calls `on_close` once it has ended, however it ended (finished, client
    gone, service stopping): the stream's place under the limit is given back even when the body
    generator never started."""

    def __init__(self, *args: object, on_close: Callable[[], None], **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._on_close = on_close

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await super().__call__(scope, receive, send)
        finally:
            self._on_close()
