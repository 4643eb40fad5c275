"""The probes for process supervisors and load balancers, open without a key (the key gate exempts their
paths by name, service.api.key_gate.EXEMPT_PATHS) and out of the OpenAPI schema:

- `GET /healthz`: liveness, the process answers. 200 {"status": "ok"}, from memory, nothing else looked at.
- `GET /readyz`: readiness, the service can do its work. Four checks, each {"ok": bool, "detail": str}:
  `database` (a `SELECT 1` within READY_DATABASE_TIMEOUT_S), `worker` (the worker process alive),
  `devices` (the bench's devices as the service knows them, see `devices_check`) and `kernel` (whether
  the compiled simulation kernel is built for this version, see `kernel_check`). 200 when all pass, else
  503 naming the failed ones in "failed". A lane whose central database is away is still ready: it works
  on its local store (GET /api/v1/status and /metrics show the sync).

Neither takes a body, and no key is looked up: a probe costs microseconds (readiness: one pooled query,
and the kernel's digest over three source files).
"""

from __future__ import annotations

import asyncio
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse

from estimator.errors import one_line
from service.store.counts import ping

if TYPE_CHECKING:
    from service.api.app import Services

router = APIRouter(tags=["operations"])

HEALTH_PATH = "/healthz"
READY_PATH = "/readyz"
READY_DATABASE_TIMEOUT_S = 2.0
"""A database that does not answer `SELECT 1` within this long counts as unreachable for readiness."""


@dataclass(frozen=True)
class Check:
    ok: bool
    detail: str


async def database_check(services: Services) -> Check:
    try:
        await asyncio.wait_for(asyncio.to_thread(ping, services.database), READY_DATABASE_TIMEOUT_S)
    except TimeoutError:
        return Check(False, f"{services.database.safe_url}: no answer within {READY_DATABASE_TIMEOUT_S:g} s")
    except Exception as exc:  # any driver's error: the probe says what it was, in one line
        return Check(False, f"{services.database.safe_url}: {type(exc).__name__}: {one_line(exc)}")
    return Check(True, services.database.safe_url)


def worker_check(services: Services) -> Check:
    status = services.manager.status()
    if not status.worker_alive:
        return Check(False, f"no worker process alive ({status.worker_restarts} restart(s) so far)")
    state = "ready" if status.worker_ready else "starting (loading the estimator)"
    return Check(True, f"pid {status.worker_pid}, {state}")


def devices_check(services: Services) -> Check:
    """Without a bench (neither --simulated nor --config) there is nothing to reach: ready for analysis.
    With one, not ready when the service is stopping, when the drive could not be commanded at start-up
    and no sweep has run since, or when a laser delivered no sample in the last sweep (its error named). A
    live check of idle devices is `shockbench probe`'s job, not a probe's."""
    bench = services.bench
    if bench is None:
        return Check(True, "no bench configured (analysis only)")
    if bench.stopping:
        return Check(False, "the service is stopping")
    progress = bench.state().progress
    if progress is None:
        if services.bench_startup is not None and not services.bench_startup.drive_reached:
            return Check(False, services.bench_startup.note)
        return Check(True, f"bench {bench.config.name!r}: no sweep since the start")
    silent = [s for s in progress.sources if s.samples == 0 and s.last_error]
    if silent:
        return Check(
            False,
            "; ".join(f"laser {s.name!r}: no sample in the last sweep ({s.last_error})" for s in silent),
        )
    return Check(
        True, f"bench {bench.config.name!r}: {len(progress.sources)} laser(s) delivered in the last sweep"
    )


def kernel_check() -> Check:
    """Always ok (numba runs the simulation without the extension built ahead of time), but the detail
    says which: without the extension each analysis process loads numba (1-3 s) and the first on a machine
    compiles the kernel (10-30 s), which an operator sees as a slow lane, not as a failure."""
    from estimator.simulation_kernel import built_extension

    name = built_extension()
    if name is not None:
        return Check(True, f"compiled ahead of time ({name})")
    return Check(
        True,
        "not built for this version: numba compiles or loads it in each process; build it with "
        "`python -m service.kernel_build`",
    )


@router.get(HEALTH_PATH, include_in_schema=False)
async def healthz() -> dict[str, str]:
    """The process answers."""
    return {"status": "ok"}


@router.get(READY_PATH, include_in_schema=False)
async def readyz(request: Request) -> JSONResponse:
    """Database, worker and devices: 200 when all pass, 503 naming the failed checks."""
    services: Services | None = getattr(request.app.state, "services", None)
    if services is None:
        return JSONResponse({"status": "starting", "failed": ["startup"], "checks": {}}, status_code=503)
    checks = {
        "database": await database_check(services),
        "worker": worker_check(services),
        "devices": devices_check(services),
        "kernel": kernel_check(),
    }
    failed = [name for name, check in checks.items() if not check.ok]
    body = {
        "status": "not ready" if failed else "ready",
        "failed": failed,
        "checks": {name: asdict(check) for name, check in checks.items()},
    }
    return JSONResponse(body, status_code=503 if failed else 200)
