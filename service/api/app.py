"""`create_app(settings)`: the FastAPI application of the bench service.

Everything is under /api/v1 (OpenAPI schema at /api/v1/openapi.json, interactive docs at /docs), but the
operations endpoints: the probes /healthz and /readyz (service.api.routes.health) and /metrics
(service.api.metrics). What the app owns (database, job store, job manager with its worker process) is made
and closed by the lifespan (no startup events) and reachable from a request as `request.app.state.services`;
its metrics registry is `app.state.metrics`.
"""

from __future__ import annotations

import asyncio
import logging
import os
import secrets
import time
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path

from fastapi import APIRouter, FastAPI
from starlette.types import ASGIApp

from daq.sweep.model import SweepOutcome
from daq.sweep.plan import SweepPlan
from service.access import KeyRing
from service.api.central_sync import SyncAgent
from service.api.contract import install_contract
from service.api.docs_page import install_docs
from service.api.errors import install_error_handlers
from service.api.input_check import CHECKER
from service.api.key_gate import KeyGate
from service.api.limits import BodyDeadline, BodyDeadlines, BodySizeLimit
from service.api.methods import AllowedMethods
from service.api.metrics import ServiceMetrics, install_metrics
from service.api.quotas import install_quotas, retention_task
from service.api.results import verdict_of
from service.api.routes import bench, events, health, jobs, live, schedules, status, sweeps, vehicles
from service.api.scheduler import InspectionScheduler
from service.api.schemas import API_PREFIX
from service.api.security_headers import SecurityHeaders
from service.api.settings import ServiceSettings
from service.api.stream_limit import StreamLimit
from service.api.web import install_page
from service.bench_control import BenchController, SweepDone
from service.jobs.manager import JobManager
from service.store.chain_anchor import HeadLog
from service.store.database import Database
from service.store.jobs import JobStore
from service.store.schedules import ScheduleStore
from service.store.sweeps import SweepStore
from service.version import shockbench_version

log = logging.getLogger("shockbench.api")


def service_version() -> str:
    """The version `shockbench --version` says (service.version: installed metadata, else the source's)."""
    return shockbench_version()


@dataclass
class Services:
    """What the running service owns. The acquisition layer adds its bench here (and starts and stops it
    in `lifespan_factory`)."""

    settings: ServiceSettings
    keys: KeyRing
    database: Database
    jobs: JobStore
    manager: JobManager
    version: str
    started_at: float
    """time.monotonic() at start-up."""
    streams: StreamLimit = field(default_factory=StreamLimit)
    """Open event streams per key."""
    sweeps: SweepStore | None = None
    bench: BenchController | None = None
    """None when the service was started without --simulated or --config: bench endpoints answer 503."""
    tests: ScheduleStore | None = None
    """Scheduled inspection-line tests."""
    scheduler: InspectionScheduler | None = None
    """Runs the scheduled tests on the bench (None without a bench)."""
    sync: SyncAgent | None = None
    """Pushes the local store to the central database (None without a local store: settings.central_url)."""
    bench_startup: BenchStartup | None = None
    """What the stop command at start-up found (None without a bench): the readiness probe's knowledge of
    the drive until a sweep has run."""

    def wake_scheduler(self) -> None:
        """Something changed (a test submitted, a sweep ended): let the scheduler look now. Any thread."""
        if self.scheduler is not None:
            self.scheduler.wake()


@dataclass(frozen=True)
class BenchStartup:
    drive_reached: bool
    note: str
    """What BenchController.stop_drive said, in words."""


STARTUP_STOP_FAILED = "could not command"
"""How BenchController.stop_drive's answer begins when no stop reached the drive."""


class ObservedBench(BenchController):
    """The bench, telling `on_sweep_end` (the metrics) how each sweep ended, after the sweep's own `done`
    (which stores it) and whatever that did."""

    on_sweep_end: Callable[[SweepOutcome | None], None] | None = None

    def start_sweep(self, sweep_id: str, plan: SweepPlan, out_path: Path, done: SweepDone) -> None:
        observe = self.on_sweep_end

        def done_then_observe(sweep_id: str, outcome: SweepOutcome | None, error: str) -> None:
            try:
                done(sweep_id, outcome, error)
            finally:
                if observe is not None:
                    try:
                        observe(outcome)
                    except Exception:  # the sweep's thread reports; metrics never stop it
                        log.exception("could not count the end of sweep %s", sweep_id)

        super().start_sweep(sweep_id, plan, out_path, done_then_observe)


def open_bench(
    settings: ServiceSettings, on_sweep_end: Callable[[SweepOutcome | None], None] | None = None
) -> tuple[BenchController | None, BenchStartup | None]:
    """The bench of `--config` (loaded and checked), its drive commanded to stop at once (a crashed
    predecessor may have left the plate running), with what that stop found; else the in-process simulated
    bench of `--simulated`; else None. Blocking (files, devices): call it in a thread."""
    bench: ObservedBench | None = None
    startup = None
    if settings.bench_config is not None:
        from daq.bench_config import load_bench_config

        bench = ObservedBench(load_bench_config(settings.bench_config))
        note = bench.stop_drive()
        startup = BenchStartup(not note.startswith(STARTUP_STOP_FAILED), note)
    elif settings.simulated:
        bench = ObservedBench(simulated=True)
    if bench is not None:
        bench.on_sweep_end = on_sweep_end
    return bench, startup


FINGERPRINT_SECRET_FILE = "key-id.secret"


def fingerprint_secret(data_dir: Path) -> bytes:
    """The secret of the key ids' HMAC (service.access.key_id), made once per data directory (32 random
    bytes, readable by the service's user only) so that the ids recorded with jobs and sweeps stay the
    same across restarts."""
    path = data_dir / FINGERPRINT_SECRET_FILE
    try:
        secret = path.read_bytes()
        if len(secret) >= 32:
            return secret
    except FileNotFoundError:
        pass
    secret = secrets.token_bytes(32)
    partial = path.with_name(f".{path.name}.{secrets.token_hex(4)}")
    descriptor = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "wb") as out:
        out.write(secret)
    os.replace(partial, path)
    return secret


Lifespan = Callable[[FastAPI], AbstractAsyncContextManager[None]]


def lifespan_factory(settings: ServiceSettings) -> Lifespan:
    """Open the database (creating tables; jobs cut off by a crash marked failed, queued jobs resumed),
    start the worker process and the job manager; on the way out stop them in reverse order."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        def prepare() -> Database:
            for folder in (settings.data_dir, settings.jobs_dir, settings.uploads_dir):
                folder.mkdir(parents=True, exist_ok=True)
            settings.keys.fingerprint_secret = fingerprint_secret(settings.data_dir)
            database = Database(settings.resolved_database_url, outbox=settings.central_url is not None)
            database.upgrade_schema()
            return database

        metrics: ServiceMetrics = app.state.metrics
        # first: the drive stops before anything
        bench, bench_startup = await asyncio.to_thread(open_bench, settings, metrics.sweep_ended)
        try:
            database = await asyncio.to_thread(prepare)
        except BaseException:
            if bench is not None:
                await asyncio.to_thread(bench.close)
            raise
        store = JobStore(database, lane=settings.lane, heads=HeadLog.in_data_dir(settings.data_dir))
        sweep_store = SweepStore(database, lane=settings.lane)
        failed_sweeps = await asyncio.to_thread(sweep_store.recover_interrupted)
        if failed_sweeps:
            log.warning("sweeps %s were cut off by a restart; marked failed", failed_sweeps)
        manager = JobManager(
            store, settings.worker, completing=verdict_of(settings.verdict), on_finished=metrics.job_finished
        )
        tests = ScheduleStore(database, lane=settings.lane)
        sync = SyncAgent(database, Database(settings.central_url)) if settings.central_url else None
        scheduler = None
        if bench is not None:
            scheduler = InspectionScheduler(settings, bench, tests, sweep_store, store, manager)
        app.state.services = Services(
            settings,
            settings.keys,
            database,
            store,
            manager,
            service_version(),
            time.monotonic(),
            streams=StreamLimit(settings.max_streams_per_key),
            sweeps=sweep_store,
            bench=bench,
            tests=tests,
            scheduler=scheduler,
            sync=sync,
            bench_startup=bench_startup,
        )
        retention = retention_task(settings, database)
        try:
            await asyncio.to_thread(CHECKER.start)
            await manager.start()
            if sync is not None:
                await sync.start()
            if scheduler is not None:
                await scheduler.start()
            if retention is not None:
                await retention.start()  # a first pass now, then every few hours (service.api.quotas)
            log.info("shockbench service up; database %s, data in %s", database.safe_url, settings.data_dir)
            yield
        finally:
            if retention is not None:
                await retention.stop()
            if scheduler is not None:
                await scheduler.stop()  # no new test starts while the bench closes
            if bench is not None:
                await asyncio.to_thread(bench.close)  # a running sweep ends (and is stored) first
            await manager.stop()
            if sync is not None:
                await sync.stop()  # after the manager: a job it ended is in the outbox, pushed next start
                sync.central.dispose()
            await asyncio.to_thread(CHECKER.close)
            database.dispose()

    return lifespan


def api_router() -> APIRouter:
    router = APIRouter(prefix=API_PREFIX)
    router.include_router(status.router)
    router.include_router(jobs.router())
    router.include_router(events.router)
    router.include_router(bench.router)
    router.include_router(live.router)
    router.include_router(sweeps.router)
    router.include_router(schedules.router)
    router.include_router(vehicles.router)
    return router


class ServiceApp(FastAPI):
    """The FastAPI app with the security headers outside everything, FastAPI's error middleware included
    (the 500 of an unexpected error carries them too)."""

    def build_middleware_stack(self) -> ASGIApp:
        return SecurityHeaders(super().build_middleware_stack())


def create_app(settings: ServiceSettings) -> FastAPI:
    """The app. Before a route reads a body (outermost first): the allowed methods (OPTIONS), the key
    gate (401 before the body), the body deadlines and the body size caps (service.api.key_gate,
    service.api.limits); the connection-level guards are in the server (service.api.server)."""
    app = ServiceApp(
        title="shockbench bench service",
        summary="On-vehicle shock absorber test bench: identification jobs, progress, results and plots.",
        version=service_version(),
        lifespan=lifespan_factory(settings),
        docs_url=None,  # install_docs: the same page, with its own security policy
        redoc_url=None,
        openapi_url=f"{API_PREFIX}/openapi.json",
    )
    app.state.settings = settings  # for the server: the connection limits
    app.state.metrics = ServiceMetrics(lambda: getattr(app.state, "services", None))
    install_error_handlers(app)
    install_quotas(app, settings)  # innermost of the body guards: an oversized body is a 413 first
    app.add_middleware(
        BodySizeLimit, max_upload_bytes=settings.max_upload_bytes, max_json_bytes=settings.max_json_bytes
    )
    deadlines = BodyDeadlines(
        pause_s=settings.body_timeout_s,
        min_rate_bytes_s=settings.body_min_rate_bytes_s,
        grace_s=settings.body_rate_grace_s,
        total_s=settings.body_total_timeout_s,
    )
    app.add_middleware(BodyDeadline, deadlines=deadlines)
    app.add_middleware(KeyGate, routes=app.router.routes, keys=settings.keys)
    app.include_router(api_router())
    app.include_router(health.router)
    install_metrics(app, app.state.metrics, settings.metrics_access)
    install_page(app)
    install_docs(app)
    install_contract(app)
    app.add_middleware(AllowedMethods, routes=app.router.routes)
    return app
