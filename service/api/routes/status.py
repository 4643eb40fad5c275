"""GET /api/v1/status: the service at a glance. Answers from memory only (no database, no worker round
trip), so it stays fast while a DE job runs. GET /api/v1/whoami: the caller's role, so that a page shows
only the controls the key may use (the API still enforces every role itself)."""

from __future__ import annotations

import time
from dataclasses import asdict
from typing import Literal

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field

from service.api.auth import Viewer
from service.api.errors import responses
from service.api.routes.bench import bench_summary
from service.api.schemas import CurrentJobOut, ProgressOut, StatusOut, SyncOut, WorkerOut

router = APIRouter(tags=["status"])


class WhoAmIOut(BaseModel):
    key_id: str = Field(description="the key's id (a keyed hash), as recorded with what it does")
    role: Literal["viewer", "operator", "admin"]


@router.get("/whoami", response_model=WhoAmIOut, operation_id="whoami", responses=responses(401, 403))
async def whoami(principal: Viewer) -> WhoAmIOut:
    """The role of the key in the Authorization header (401 when it is not a valid key)."""
    return WhoAmIOut(key_id=principal.key_id, role=principal.role.label)  # type: ignore[arg-type]


@router.get("/status", response_model=StatusOut, operation_id="get_status", responses=responses(401, 403))
async def get_status(request: Request, _principal: Viewer) -> StatusOut:
    """Version, worker process, queue, the job that runs now, the bench (null without one), and the sync
    backlog of the lane's local store (null without one)."""
    services = request.app.state.services
    s = services.manager.status()
    current = (
        CurrentJobOut(
            id=s.current_job_id, kind=s.current_kind or "", progress=ProgressOut.of(s.current_progress)
        )
        if s.current_job_id is not None
        else None
    )
    return StatusOut(
        version=services.version,
        lane=services.settings.lane,
        uptime_s=time.monotonic() - services.started_at,
        worker=WorkerOut(
            alive=s.worker_alive, ready=s.worker_ready, pid=s.worker_pid, restarts=s.worker_restarts
        ),
        queue_length=s.queue_length,
        current_job=current,
        bench=bench_summary(request),
        sync=SyncOut(**asdict(services.sync.status())) if services.sync is not None else None,
    )
