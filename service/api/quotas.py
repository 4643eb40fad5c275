"""What one client may make the service keep: quotas per key, free disk for uploads, and retention.

- Jobs per key (`serve --max-queued-jobs-per-key`, default 20): a submit whose key has that many jobs
  queued or running is answered 429 with Retry-After; the check is in the transaction that inserts the job
  (service.store.quota says why that and no lock here). Scheduled tests likewise
  (`--max-scheduled-tests-per-key`, waiting or running). Jobs the service queues itself (the scheduler's,
  on a finished test's sweep) are not counted against a limit.
- Free disk (`--min-free-mb`, default 1 GiB): a multipart upload is answered 507 before its body is read
  (so before anything of it reaches a disk) when the data directory's file system has less than that
  free, or would have once the declared Content-Length is stored. The free-space function is a setting
  (ServiceSettings.disk_free_bytes) so that tests simulate a full disk.
- Retention (`--retain-days`, default 90; service.store.retention): old uploaded inputs, old sweep
  recordings and stale partial uploads are deleted at start-up and every RETENTION_INTERVAL_S.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from service.access import Principal
from service.api.errors import ErrorBody, error_response
from service.api.key_gate import declared_length
from service.api.settings import ServiceSettings
from service.store.database import Database
from service.store.quota import KeyQuota, QuotaExceededError
from service.store.retention import RetentionPolicy, run_retention

log = logging.getLogger("shockbench.api")

RETRY_AFTER_S = 30
"""Retry-After of a 429 over the job quota: an identification takes seconds to a few minutes, so one of the
key's jobs has likely ended by then."""
RETENTION_INTERVAL_S = 6 * 3600.0
"""Retention runs at start-up and then this often: a few times a day is plenty for a limit in days."""
QUOTA_RESPONSES: dict[int | str, dict[str, Any]] = {
    429: {
        "model": ErrorBody,
        "description": "the key has as many unfinished jobs (scheduled tests) as allowed; see Retry-After",
    }
}
STORAGE_RESPONSES: dict[int | str, dict[str, Any]] = {
    507: {"model": ErrorBody, "description": "too little free disk in the data directory for the upload"}
}
"""OpenAPI documentation of the quota answers, for the routes that can give them."""


def job_quota(settings: ServiceSettings, principal: Principal) -> KeyQuota:
    return KeyQuota(principal.key_id, settings.max_queued_jobs_per_key)


def schedule_quota(settings: ServiceSettings, principal: Principal) -> KeyQuota:
    return KeyQuota(principal.key_id, settings.max_scheduled_tests_per_key)


async def _over_quota(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, QuotaExceededError)
    return error_response(429, "too_many_requests", str(exc), headers={"Retry-After": str(RETRY_AFTER_S)})


def _megabytes(count: int) -> str:
    return f"{count / 2**20:.1f} MiB"


class StorageGuard:
    """Pure ASGI middleware: a multipart POST (an upload) is answered 507 before its body is read when the
    data directory's file system has less than `min_free_bytes` free, counting the declared
    Content-Length (a chunked body counts as empty; the upload size limit bounds it)."""

    def __init__(
        self, app: ASGIApp, data_dir: Path, min_free_bytes: int, free: Callable[[Path], int]
    ) -> None:
        self.app = app
        self.data_dir = data_dir
        self.min_free_bytes = min_free_bytes
        self.free = free

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] == "POST":
            headers = dict(scope.get("headers") or [])
            if headers.get(b"content-type", b"").lower().startswith(b"multipart/"):
                refusal = await self._refusal(max(declared_length(scope) or 0, 0))
                if refusal is not None:
                    await error_response(507, "insufficient_storage", refusal)(scope, receive, send)
                    return
        await self.app(scope, receive, send)

    async def _refusal(self, length: int) -> str | None:
        """Why an upload of `length` bytes is refused (0: none declared, or a malformed Content-Length,
        which the upload size limit answers), or None."""
        free = await asyncio.to_thread(self.free, self.data_dir)
        if free - length >= self.min_free_bytes:
            return None
        kept = f"the {_megabytes(self.min_free_bytes)} the service keeps free"
        if free < self.min_free_bytes:
            return f"the data directory has {_megabytes(free)} free, less than {kept}; try again later"
        return (
            f"the data directory has {_megabytes(free)} free; this upload ({_megabytes(length)}) would "
            f"leave less than {kept}; try again later"
        )


def install_quotas(app: FastAPI, settings: ServiceSettings) -> None:
    """The 429 of a quota, and the free-disk check of uploads (call before the body limits are added, so
    that an oversized body is still a 413)."""
    app.add_exception_handler(QuotaExceededError, _over_quota)
    app.add_middleware(
        StorageGuard,
        data_dir=settings.data_dir,
        min_free_bytes=settings.min_free_bytes,
        free=settings.disk_free_bytes,
    )


def retention_policy(settings: ServiceSettings) -> RetentionPolicy | None:
    """None when retention is off (`--retain-days 0`). On a database shared by lanes, only this lane's
    (and pre-lane) jobs and sweeps: the others' files are on their own machines; and the recordings stored
    in it stay (the fleet's archive). On the data directory's own database (or local store), their stored
    copies go too."""
    if settings.retain_days is None:
        return None
    shared = settings.database_url is not None and not settings.local_store
    lanes = (settings.lane, "") if shared else None
    return RetentionPolicy(settings.retain_days, lanes=lanes, stored_copies=not shared)


class RetentionTask:
    """Retention passes in a thread: one at start-up, then every RETENTION_INTERVAL_S until stopped. A
    pass that has begun is let finish on stop (it uses the database, which is closed after)."""

    def __init__(self, settings: ServiceSettings, database: Database, policy: RetentionPolicy) -> None:
        self.settings = settings
        self.database = database
        self.policy = policy
        self._stopping = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    async def run_once(self) -> None:
        try:
            await asyncio.to_thread(run_retention, self.database, self.settings.data_dir, self.policy)
        except Exception:  # a failed pass must not stop the service; the next one tries again
            log.exception("retention pass failed")

    async def _repeat(self) -> None:
        while True:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stopping.wait(), RETENTION_INTERVAL_S)
                return
            await self.run_once()

    async def start(self) -> None:
        """The first pass (awaited: the service starts with old files gone), then the repeating task."""
        await self.run_once()
        self._task = asyncio.create_task(self._repeat(), name="retention")

    async def stop(self) -> None:
        self._stopping.set()
        if self._task is not None:
            await self._task


def retention_task(settings: ServiceSettings, database: Database) -> RetentionTask | None:
    """The service's retention (start and stop it in the lifespan); None when it is off."""
    policy = retention_policy(settings)
    return RetentionTask(settings, database, policy) if policy is not None else None
