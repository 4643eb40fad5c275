"""At most N open event streams per key (`serve --max-streams-per-key`).

An event stream holds a connection and a queue in the service for as long as its job runs; a client that
opens streams in a loop (a dashboard reloading, a script without a `with`) would hold them all. Each key
may have `limit` streams open at once; one more is refused with 429 and a Retry-After, until one ends.
Everything runs on the event loop: a counter per key, no lock needed.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager

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

    @contextmanager
    def held(self, key_id: str) -> Iterator[None]:
        """One stream of `key_id` for the block (acquire, ApiError 429 when full), given back however the
        block ends. The streams hold it in a dependency with yield, which ends once the response has."""
        self.acquire(key_id)
        try:
            yield
        finally:
            self.release(key_id)

    def release(self, key_id: str) -> None:
        self._open[key_id] -= 1
        if self._open[key_id] <= 0:
            del self._open[key_id]
