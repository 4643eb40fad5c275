"""Everything the service is started with, in one object that `shockbench serve` (or a test) builds and
`create_app` takes. The limits' defaults, bounds and help are declared once in service.service_limits."""

from __future__ import annotations

import shutil
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, get_args

from estimator.verdict import VerdictThresholds
from service.access import KeyRing
from service.jobs.manager import WorkerSettings
from service.service_limits import LIMITS
from service.store.database import default_database_url

DEFAULT_MAX_STREAMS_PER_KEY = LIMITS.max_streams_per_key
DEFAULT_BODY_TIMEOUT_S = LIMITS.body_timeout_s
DEFAULT_MAX_UPLOAD_BYTES = LIMITS.max_upload_bytes
DEFAULT_MAX_JSON_BYTES = LIMITS.max_json_bytes
DEFAULT_HEADER_TIMEOUT_S = LIMITS.header_timeout_s
DEFAULT_BODY_MIN_RATE_BYTES_S = LIMITS.body_min_rate_bytes_s
DEFAULT_BODY_RATE_GRACE_S = LIMITS.body_rate_grace_s
DEFAULT_BODY_TOTAL_TIMEOUT_S = LIMITS.body_total_timeout_s
DEFAULT_MAX_CONNECTIONS_PER_ADDRESS = LIMITS.max_connections_per_address
DEFAULT_MAX_QUEUED_JOBS_PER_KEY = LIMITS.max_queued_jobs_per_key
DEFAULT_MAX_SCHEDULED_TESTS_PER_KEY = LIMITS.max_scheduled_tests_per_key
DEFAULT_MIN_FREE_BYTES = LIMITS.min_free_bytes
"""The limits' defaults, each declared once with its unit, bounds, help and reason in
service.service_limits (which `shockbench serve`'s options come from too)."""


MetricsAccess = Literal["admin", "key", "open"]
"""Who may read GET /metrics (service.api.metrics): an admin key, any valid key, or anyone."""
METRICS_ACCESS: tuple[str, ...] = get_args(MetricsAccess)


def disk_free_bytes(path: Path) -> int:
    """Free bytes on the file system of `path` for the service's user."""
    return shutil.disk_usage(path).free


@dataclass(frozen=True)
class ServiceSettings:
    data_dir: Path
    """Uploaded inputs and job artefacts (jobs/<id>/), and the SQLite database unless database_url says
    otherwise."""
    keys: KeyRing
    database_url: str | None = None
    """Any SQLAlchemy URL; None: SQLite in data_dir. With `local_store`, the central database."""
    local_store: bool = False
    """Run on a local store (SQLite in data_dir) and sync finished sweeps and jobs to `database_url`, the
    central database, when it is reachable (service.store.sync; `serve --database` without
    `--shared-queue`)."""
    bench_config: Path | None = None
    """Bench configuration (TOML), for the acquisition layer."""
    simulated: bool = False
    """Start simulated devices, so that the whole service runs with nothing attached."""
    max_upload_bytes: int = DEFAULT_MAX_UPLOAD_BYTES
    body_timeout_s: float = DEFAULT_BODY_TIMEOUT_S
    """A request body that brings nothing for this long before it is complete is answered 408."""
    max_json_bytes: int = DEFAULT_MAX_JSON_BYTES
    """Size cap of a request body on every route but the multipart uploads (max_upload_bytes); over: 413."""
    header_timeout_s: float = DEFAULT_HEADER_TIMEOUT_S
    """A connection whose request headers are not complete this long after it began waiting for them is
    closed (service.api.connection_limits)."""
    body_min_rate_bytes_s: float = DEFAULT_BODY_MIN_RATE_BYTES_S
    """After body_rate_grace_s, a request body slower than this on average is answered 408 (0: no
    minimum)."""
    body_rate_grace_s: float = DEFAULT_BODY_RATE_GRACE_S
    body_total_timeout_s: float = DEFAULT_BODY_TOTAL_TIMEOUT_S
    """A request body not complete within this long is answered 408."""
    max_connections_per_address: int = DEFAULT_MAX_CONNECTIONS_PER_ADDRESS
    """Open connections one client address may hold; a connection beyond is closed at once."""
    max_streams_per_key: int = DEFAULT_MAX_STREAMS_PER_KEY
    """Event streams one key may hold open at once; one more is answered 429."""
    max_queued_jobs_per_key: int = DEFAULT_MAX_QUEUED_JOBS_PER_KEY
    """Jobs one key may have queued or running at once; one more submit is answered 429
    (service.api.quotas)."""
    max_scheduled_tests_per_key: int = DEFAULT_MAX_SCHEDULED_TESTS_PER_KEY
    """Scheduled tests one key may have waiting or running at once; one more is answered 429."""
    min_free_bytes: int = DEFAULT_MIN_FREE_BYTES
    """An upload that would leave less free on the data directory's file system is answered 507."""
    retain_days: float | None = LIMITS.retain_days
    """Uploaded inputs of finished jobs and sweep recordings older than this are deleted
    (service.store.retention); None: kept for ever."""
    disk_free_bytes: Callable[[Path], int] = field(default=disk_free_bytes, repr=False, compare=False)
    """How free space is measured (tests simulate a full disk with their own)."""
    worker: WorkerSettings = field(default_factory=WorkerSettings)
    lane: str = field(default_factory=socket.gethostname)
    """This instance's lane (`serve --lane`, default the host name): stamped on its sweeps, jobs and
    scheduled tests; its scheduler runs only its own lane's tests."""
    metrics_access: MetricsAccess = "admin"
    """Who may read GET /metrics (service.api.metrics): "admin" an admin key, "key" any valid key, "open"
    anyone (a monitoring network the service's port is reachable from only)."""
    verdict: VerdictThresholds = field(default_factory=VerdictThresholds)
    """The limits an identification's lane figures are judged by (estimator.verdict; serve
    --verdict-thresholds): the verdict is stored with the result when the job ends."""

    @property
    def resolved_database_url(self) -> str:
        """The database the service runs on: the local store, else `database_url`."""
        if self.local_store or not self.database_url:
            return default_database_url(self.data_dir)
        return self.database_url

    @property
    def central_url(self) -> str | None:
        """The central database the local store is synced to; None without a local store."""
        return self.database_url if self.local_store else None

    @property
    def jobs_dir(self) -> Path:
        return self.data_dir / "jobs"

    @property
    def uploads_dir(self) -> Path:
        """Uploads land here while they are checked, then move to their job's folder."""
        return self.data_dir / "uploads"
