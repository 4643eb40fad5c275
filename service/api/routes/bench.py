"""The bench: its state (GET /bench, memory only), its devices, and the emergency stop.

The bench exists when the service was started with --simulated or --config; without one these endpoints
answer 503 (code no_bench).
"""

from __future__ import annotations

import asyncio
import logging

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field

from service.api.auth import Operator, Viewer
from service.api.errors import ApiError, responses
from service.api.schemas import BenchOut, SweepProgressOut
from service.bench_control import BenchController

router = APIRouter(tags=["bench"])
log = logging.getLogger("shockbench.api")

NO_BENCH = "no bench: start serve with --simulated or --config"


def require_bench(request: Request) -> BenchController:
    bench: BenchController | None = request.app.state.services.bench
    if bench is None:
        raise ApiError(503, NO_BENCH, code="no_bench")
    return bench


class DevicesOut(BaseModel):
    devices: list[dict[str, str]] = Field(
        description="what the bench configuration names: name, kind (exciter, laser), url (and channel, "
        "head for a laser), and state: in words, what it does or delivered in the running or last sweep"
    )


class EmergencyStopOut(BaseModel):
    done: str = Field(description="what was done, in words")
    sweep_id: int | None = Field(None, description="the sweep that was running, if one was")


def bench_out(bench: BenchController) -> BenchOut:
    state = bench.state()
    running = state.busy and state.sweep_id is not None
    return BenchOut(
        name=state.name,
        model=state.model,
        simulated=state.simulated,
        busy=state.busy,
        sweep_id=int(state.sweep_id) if running and state.sweep_id else None,
        progress=SweepProgressOut.of(state.progress) if running else None,
    )


def bench_summary(request: Request) -> BenchOut | None:
    """For GET /status: the bench at a glance, from memory (None without a bench)."""
    bench: BenchController | None = request.app.state.services.bench
    if bench is None:
        return None
    return bench_out(bench)


@router.get("/bench", response_model=BenchOut, operation_id="get_bench", responses=responses(401, 403, 503))
async def get_bench(request: Request, _principal: Viewer) -> BenchOut:
    """The bench: name, model, simulated or not, busy, and the running sweep with its progress. From
    memory only: fast while a sweep runs."""
    return bench_out(require_bench(request))


@router.get(
    "/bench/devices",
    response_model=DevicesOut,
    operation_id="list_devices",
    responses=responses(401, 403, 503),
)
async def get_devices(request: Request, _principal: Viewer) -> DevicesOut:
    """The devices the bench configuration names (a live check is `shockbench probe`'s job)."""
    return DevicesOut(devices=require_bench(request).devices())


@router.post(
    "/emergency-stop",
    response_model=EmergencyStopOut,
    operation_id="emergency_stop",
    responses=responses(401, 403, 503),
)
async def emergency_stop(request: Request, _principal: Operator) -> EmergencyStopOut:
    """Emergency stop of the plate. A running sweep ends with it (its recording kept, the sweep failed
    with reason "emergency stop by the operator"); with no sweep running the command goes straight to
    the drive."""
    bench = require_bench(request)
    state = bench.state()
    try:
        done = await asyncio.to_thread(bench.emergency_stop)
    except Exception as exc:  # the drive unreachable: say so, loudly, not as a bare 500
        log.error("emergency stop failed", exc_info=exc)
        raise ApiError(
            503, f"emergency stop failed: {type(exc).__name__}: {exc}", code="emergency_stop_failed"
        ) from None
    sweep_id = int(state.sweep_id) if state.busy and state.sweep_id else None
    return EmergencyStopOut(done=done, sweep_id=sweep_id)
