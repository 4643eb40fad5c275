"""`GET /metrics`: the service's metrics in Prometheus' text format, with the official prometheus-client.

Each app has its own `CollectorRegistry` (never the library's global one), so that several apps in one
process (tests) keep their numbers apart. Two kinds of metrics:

- observed as things happen, in memory since the start (counters and histograms): how long each job ran
  (`shockbench_job_duration_seconds`, by kind and outcome; the job manager reports each end), and what
  each sweep's acquisition delivered (rows, rows with a gap, and per channel the samples, lost samples
  and failed reads; the bench reports each sweep's end);
- read at scrape time (`StateCollector`): the lane's jobs by kind and state and its sweeps by state from
  the database, the queue depth, the worker and its restarts, the bench, the central sync's backlog, from
  memory. The database is read in the scrape's thread (the route runs the scrape off the event loop);
  when it does not answer, `shockbench_database_up` is 0 and the database-backed series are left out.

Who may read it is the setting `metrics_access` (serve --metrics-access): "admin" (default) an admin key,
"key" any valid key, "open" anyone. The names are listed in docs/operations.md.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

from fastapi import Depends, FastAPI, Response
from prometheus_client import (
    CONTENT_TYPE_LATEST,
    CollectorRegistry,
    Counter,
    GCCollector,
    Histogram,
    PlatformCollector,
    ProcessCollector,
    generate_latest,
)
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, InfoMetricFamily, Metric
from prometheus_client.registry import Collector
from sqlalchemy.exc import SQLAlchemyError

from daq.sweep.model import SweepOutcome
from service.access import Role
from service.api.auth import require
from service.api.settings import METRICS_ACCESS, MetricsAccess
from service.store.counts import job_counts, sweep_counts

if TYPE_CHECKING:
    from service.api.app import Services

log = logging.getLogger("shockbench.metrics")

METRICS_PATH = "/metrics"
METRICS_GATES = {"admin": require(Role.ADMIN), "key": require(Role.VIEWER)}
"""The key check of each `metrics_access` but "open" (made once: service.api.auth registers each check)."""
JOB_DURATION_BUCKETS_S = (1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0)
"""A validation takes about a second, an identification of a quarter car 10-60 s, a diagnosis or an axle
with many DE generations minutes."""
NAMESPACE = "shockbench"


class ServiceMetrics:
    """The app's registry and the metrics observed as things happen. `services` gives the running
    service's parts (None before the lifespan started them) to the collector read at scrape time."""

    def __init__(self, services: Callable[[], Services | None]) -> None:
        self.registry = CollectorRegistry()
        registry = self.registry
        self.job_duration = Histogram(
            "job_duration_seconds",
            "Wall time of each job this instance ran, from leaving the queue to its end (s)",
            ["kind", "outcome"],
            namespace=NAMESPACE,
            buckets=JOB_DURATION_BUCKETS_S,
            registry=registry,
        )
        self.acquisition_rows = Counter(
            "acquisition_rows",
            "Rows the bench recorded in its sweeps",
            namespace=NAMESPACE,
            registry=registry,
        )
        self.acquisition_gap_rows = Counter(
            "acquisition_gap_rows",
            "Recorded rows with a gap (a channel without a sample)",
            namespace=NAMESPACE,
            registry=registry,
        )
        self.acquisition_samples = Counter(
            "acquisition_samples",
            "Samples each laser delivered",
            ["channel"],
            namespace=NAMESPACE,
            registry=registry,
        )
        self.acquisition_lost_samples = Counter(
            "acquisition_lost_samples",
            "Samples a streaming amplifier took that no poll got in time (holes in the data)",
            ["channel"],
            namespace=NAMESPACE,
            registry=registry,
        )
        self.acquisition_failed_reads = Counter(
            "acquisition_failed_reads",
            "Reads of a laser amplifier that failed",
            ["channel"],
            namespace=NAMESPACE,
            registry=registry,
        )
        registry.register(StateCollector(services))
        ProcessCollector(registry=registry)
        PlatformCollector(registry=registry)
        GCCollector(registry=registry)

    def job_finished(self, kind: str, outcome: str, duration_s: float) -> None:
        """The job manager's report of a job's end (any thread)."""
        self.job_duration.labels(kind=kind, outcome=outcome).observe(duration_s)

    def sweep_ended(self, outcome: SweepOutcome | None) -> None:
        """The bench's report of a sweep's end (the sweep's thread); None: it never began."""
        if outcome is None:
            return
        self.acquisition_rows.inc(outcome.rows)
        self.acquisition_gap_rows.inc(outcome.gap_rows)
        for source in outcome.sources:
            self.acquisition_samples.labels(channel=source.channel).inc(source.samples)
            self.acquisition_lost_samples.labels(channel=source.channel).inc(source.lost_samples)
            self.acquisition_failed_reads.labels(channel=source.channel).inc(source.failed_reads)

    def exposition(self) -> bytes:
        """The registry in the text format (reads the database: blocking)."""
        return generate_latest(self.registry)


def _gauge(name: str, documentation: str, value: float) -> GaugeMetricFamily:
    return GaugeMetricFamily(f"{NAMESPACE}_{name}", documentation, value=value)


class StateCollector(Collector):
    """The service's state at scrape time (see the module docstring)."""

    def __init__(self, services: Callable[[], Services | None]) -> None:
        self.services = services

    def collect(self) -> Iterator[Metric]:
        services = self.services()
        if services is None:  # not started (or stopped): nothing but the registry's own metrics
            return
        info = InfoMetricFamily(
            f"{NAMESPACE}_build", "The service's version and lane", labels=["version", "lane"]
        )
        info.add_metric([services.version, services.settings.lane], {})
        yield info
        manager = services.manager.status()
        yield _gauge(
            "job_queue_depth", "Jobs waiting in the queue this instance takes from", manager.queue_length
        )
        yield _gauge("worker_up", "1 while the worker process is alive", int(manager.worker_alive))
        yield CounterMetricFamily(
            f"{NAMESPACE}_worker_restarts",
            "Worker processes started after one died",
            value=manager.worker_restarts,
        )
        yield from self._stored(services)
        if services.bench is not None:
            yield _gauge("bench_busy", "1 while a sweep runs on the bench", int(services.bench.busy))
        if services.sync is not None:
            yield from _sync(services)

    def _stored(self, services: Services) -> Iterator[Metric]:
        lane = services.settings.lane
        try:
            jobs = job_counts(services.database, lane)
            sweeps = sweep_counts(services.database, lane)
        except SQLAlchemyError as exc:
            log.warning("metrics: the database did not answer: %s", str(exc).splitlines()[0])
            yield _gauge("database_up", "1 when the database answered this scrape", 0)
            return
        yield _gauge("database_up", "1 when the database answered this scrape", 1)
        by_state = GaugeMetricFamily(
            f"{NAMESPACE}_jobs", "The lane's jobs in the database by kind and state", labels=["kind", "state"]
        )
        for (kind, state), count in sorted(jobs.items()):
            by_state.add_metric([kind, state], count)
        yield by_state
        outcomes = GaugeMetricFamily(
            f"{NAMESPACE}_sweeps",
            "The lane's sweeps in the database by state (complete, failed, aborted: their outcomes)",
            labels=["state"],
        )
        for state, count in sorted(sweeps.items()):
            outcomes.add_metric([state], count)
        yield outcomes


def _sync(services: Services) -> Iterator[Metric]:
    """The central sync's view from its last round (memory only)."""
    assert services.sync is not None
    status = services.sync.status()
    yield _gauge("sync_backlog", "Finished sweeps and jobs not yet on the central database", status.backlog)
    age_s = (
        0.0 if status.oldest_pending is None else max(0.0, time.time() - status.oldest_pending.timestamp())
    )
    yield _gauge("sync_oldest_pending_age_seconds", "Age of the oldest entry waiting for the sync (s)", age_s)
    yield _gauge(
        "sync_reachable",
        "1 when the last sync round reached the central database",
        int(bool(status.reachable)),
    )
    yield CounterMetricFamily(
        f"{NAMESPACE}_sync_pushed",
        "Sweeps and jobs pushed to the central database since the start",
        value=status.pushed,
    )


def install_metrics(app: FastAPI, metrics: ServiceMetrics, access: MetricsAccess) -> None:
    """GET /metrics (out of the OpenAPI schema, like the probes), behind the key check `access` names."""
    if access not in METRICS_ACCESS:
        raise ValueError(f"metrics_access must be one of {', '.join(METRICS_ACCESS)}, not {access!r}")
    gate = METRICS_GATES.get(access)

    @app.get(METRICS_PATH, include_in_schema=False, dependencies=[Depends(gate)] if gate else [])
    async def scrape() -> Response:
        body = await asyncio.to_thread(metrics.exposition)
        return Response(body, media_type=CONTENT_TYPE_LATEST)
