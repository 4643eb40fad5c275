"""Fan-out of job events to live listeners (the Server-Sent Events streams), on the event loop.

Each listener has a bounded queue. A slow listener loses the oldest events first, so it can miss
intermediate progress but never the final event, which is always the last one published for a job.
"""

from __future__ import annotations

import asyncio
from collections import defaultdict
from dataclasses import dataclass

from service.jobs.messages import Progress
from service.store.jobs import JobRecord


@dataclass(frozen=True)
class JobStateEvent:
    """The job changed status (it left the queue, or started)."""

    job_id: int
    record: JobRecord


@dataclass(frozen=True)
class JobProgressEvent:
    """New progress from the job's worker."""

    job_id: int
    progress: Progress


@dataclass(frozen=True)
class JobFinishedEvent:
    """The job reached its final status (as written): nothing follows."""

    job_id: int
    record: JobRecord


@dataclass(frozen=True)
class JobClosingEvent:
    """The service is stopping: nothing follows."""

    job_id: int


JobEvent = JobStateEvent | JobProgressEvent | JobFinishedEvent | JobClosingEvent
"""What a listener of one job hears, each with its own typed payload."""


class EventBroker:
    def __init__(self, queue_size: int = 256) -> None:
        self._size = queue_size
        self._listeners: dict[int, set[asyncio.Queue[JobEvent]]] = defaultdict(set)
        self.closing = False

    def subscribe(self, job_id: int) -> asyncio.Queue[JobEvent]:
        queue: asyncio.Queue[JobEvent] = asyncio.Queue(self._size)
        self._listeners[job_id].add(queue)
        if self.closing:
            queue.put_nowait(JobClosingEvent(job_id))
        return queue

    def close(self) -> None:
        """The service is stopping: every listener gets `closing`, so that its stream ends now instead
        of holding up the server's shutdown."""
        self.closing = True
        for job_id in list(self._listeners):
            self.publish(JobClosingEvent(job_id))

    def unsubscribe(self, job_id: int, queue: asyncio.Queue[JobEvent]) -> None:
        listeners = self._listeners.get(job_id)
        if listeners is not None:
            listeners.discard(queue)
            if not listeners:
                del self._listeners[job_id]

    def publish(self, event: JobEvent) -> None:
        for queue in list(self._listeners.get(event.job_id, ())):
            if queue.full():
                queue.get_nowait()
            queue.put_nowait(event)

    def listeners(self, job_id: int) -> int:
        return len(self._listeners.get(job_id, ()))
