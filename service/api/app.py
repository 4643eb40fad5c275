"""`create_app(settings)`: the FastAPI application of the bench service.

Everything is under /api/v1 (OpenAPI schema at /api/v1/openapi.json, interactive docs at /docs). What the
app owns (database, job store, job manager with its worker process) is made and closed by the lifespan
(no startup events) and reachable from a request as `request.app.state.services`.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter, FastAPI

from service.access import KeyRing
from service.api.contract import install_contract
from service.api.errors import install_error_handlers
from service.api.limits import UploadSizeLimit
from service.api.routes import bench, events, jobs, schedules, status, sweeps
from service.api.scheduler import InspectionScheduler
from service.api.schemas import API_PREFIX
from service.api.settings import ServiceSettings
from service.bench_control import BenchController
from service.jobs.manager import JobManager
from service.store.database import Database
from service.store.jobs import JobStore
from service.store.schedules import ScheduleStore
from service.store.sweeps import SweepStore

log = logging.getLogger("shockbench.api")


def service_version() -> str:
    try:
        return version("shockbench")
    except PackageNotFoundError:
        return "0+unknown"


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
    sweeps: SweepStore | None = None
    bench: BenchController | None = None
    """None when the service was started without --simulated or --config: bench endpoints answer 503."""
    tests: ScheduleStore | None = None
    """Scheduled inspection-line tests."""
    scheduler: InspectionScheduler | None = None
    """Runs the scheduled tests on the bench (None without a bench)."""

    def wake_scheduler(self) -> None:
        """Something changed (a test submitted, a sweep ended): let the scheduler look now. Any thread."""
        if self.scheduler is not None:
            self.scheduler.wake()


def open_bench(settings: ServiceSettings) -> BenchController | None:
    """The bench of `--config` (loaded and checked), else the in-process simulated bench of `--simulated`,
    else None. Blocking (files, simulated devices starting): call it in a thread."""
    if settings.bench_config is not None:
        from daq.bench_config import load_bench_config

        return BenchController(load_bench_config(settings.bench_config))
    if settings.simulated:
        return BenchController(simulated=True)
    return None


Lifespan = Callable[[FastAPI], AbstractAsyncContextManager[None]]


def lifespan_factory(settings: ServiceSettings) -> Lifespan:
    """Open the database (creating tables; jobs cut off by a crash marked failed, queued jobs resumed),
    start the worker process and the job manager; on the way out stop them in reverse order."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        def prepare() -> Database:
            for folder in (settings.data_dir, settings.jobs_dir, settings.uploads_dir):
                folder.mkdir(parents=True, exist_ok=True)
            database = Database(settings.resolved_database_url)
            database.create_tables()
            return database

        database = await asyncio.to_thread(prepare)
        store = JobStore(database)
        sweep_store = SweepStore(database)
        failed_sweeps = await asyncio.to_thread(sweep_store.recover_interrupted)
        if failed_sweeps:
            log.warning("sweeps %s were cut off by a restart; marked failed", failed_sweeps)
        bench = await asyncio.to_thread(open_bench, settings)
        manager = JobManager(store, settings.worker)
        tests = ScheduleStore(database)
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
            sweeps=sweep_store,
            bench=bench,
            tests=tests,
            scheduler=scheduler,
        )
        try:
            await manager.start()
            if scheduler is not None:
                await scheduler.start()
            log.info("shockbench service up; database %s, data in %s", database.safe_url, settings.data_dir)
            yield
        finally:
            if scheduler is not None:
                await scheduler.stop()  # no new test starts while the bench closes
            if bench is not None:
                await asyncio.to_thread(bench.close)  # a running sweep ends (and is stored) first
            await manager.stop()
            database.dispose()

    return lifespan


def api_router() -> APIRouter:
    router = APIRouter(prefix=API_PREFIX)
    router.include_router(status.router)
    router.include_router(jobs.router())
    router.include_router(events.router)
    router.include_router(bench.router)
    router.include_router(sweeps.router)
    router.include_router(schedules.router)
    return router


def create_app(settings: ServiceSettings) -> FastAPI:
    app = FastAPI(
        title="shockbench bench service",
        summary="On-vehicle shock absorber test bench: identification jobs, progress, results and plots.",
        version=service_version(),
        lifespan=lifespan_factory(settings),
        docs_url="/docs",
        redoc_url=None,
        openapi_url=f"{API_PREFIX}/openapi.json",
    )
    install_error_handlers(app)
    app.add_middleware(UploadSizeLimit, max_bytes=settings.max_upload_bytes)
    app.include_router(api_router())
    install_contract(app)
    return app
