"""Everything the service is started with, in one object that `shockbench serve` (or a test) builds and
`create_app` takes."""

from __future__ import annotations

import socket
from dataclasses import dataclass, field
from pathlib import Path

from estimator.verdict import VerdictThresholds
from service.access import KeyRing
from service.jobs.manager import WorkerSettings
from service.store.database import default_database_url

DEFAULT_MAX_STREAMS_PER_KEY = 8
DEFAULT_BODY_TIMEOUT_S = 30.0
"""Longest pause within a request body (s): generous for a slow link, short enough that clients which
declare more than they send cannot hold connections for ever."""
DEFAULT_MAX_UPLOAD_BYTES = 64 * 1024 * 1024
"""64 MiB: a 20 s quarter-car recording at 1 kHz is about 1 MB of CSV, a 10-minute axle recording ~40 MB."""


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
    max_streams_per_key: int = DEFAULT_MAX_STREAMS_PER_KEY
    """Event streams one key may hold open at once; one more is answered 429."""
    worker: WorkerSettings = field(default_factory=WorkerSettings)
    lane: str = field(default_factory=socket.gethostname)
    """This instance's lane (`serve --lane`, default the host name): stamped on its sweeps, jobs and
    scheduled tests; its scheduler runs only its own lane's tests."""
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
