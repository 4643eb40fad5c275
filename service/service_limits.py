"""The service's limits, declared once: request sizes and deadlines, connections, quotas per key, free disk
and retention, each with its unit, bounds and help (estimator.declared). ServiceSettings
(service.api.settings) takes its defaults from here and `shockbench serve` its options (service.cli.serve:
the flag, its unit, default, range check and help), each also from its SHOCKBENCH_ variable.

Standard library only: `shockbench --help` builds serve's parser from these declarations without loading
the service. Why each default is what it is:

- max_upload_bytes 64 MiB: a 20 s quarter-car recording at 1 kHz is about 1 MB of CSV, a 10-minute axle
  recording ~40 MB.
- max_json_bytes 1 MiB + 64 KiB for the JSON bodies (every route but the uploads): the largest field, the
  vehicle text, is at most 1,000,000 characters; the rest covers its escaping and the other fields.
- body_timeout_s 30 s: generous for a slow link, short enough that clients which declare more than they
  send cannot hold connections for ever. header_timeout_s 10 s: headers are a few hundred bytes.
- body_min_rate_bytes_s 1 KiB/s after body_rate_grace_s 5 s: any real link (a 2G modem gives 5 KiB/s)
  keeps to it; a trickle of a byte every few seconds is cut after ~6 s.
- body_total_timeout_s 300 s: a 64 MiB upload needs 1.8 Mbit/s on average, which a poor workshop Wi-Fi
  still gives.
- max_connections_per_address 64: ten times what a browser opens to one site (6) and room for a script's
  pool, small enough that one address cannot hold the service's sockets.
- max_queued_jobs_per_key 20: an operator re-running a day's few tests, or a script re-analysing a batch,
  stays well below; a runaway client (931 jobs in five minutes) is stopped at 20.
- max_scheduled_tests_per_key 100: about two days of a busy inspection line.
- min_free_bytes 1 GiB: room for the recordings of the sweeps under way and for the database and logs to
  grow, whatever uploads arrive.
- retain_days 90 (service.store.retention's default; tests/test_declarations_agree.py checks it).
"""

from __future__ import annotations

from dataclasses import dataclass

from estimator.declared import setting

MiB = 2**20
KiB = 2**10


@dataclass(frozen=True)
class ServiceLimits:
    """What the service accepts from its clients and keeps on its disk (see the module docstring)."""

    max_upload_bytes: int = setting(64 * MiB, "upload size limit", unit="bytes", gt=0)
    max_streams_per_key: int = setting(
        8, "event streams one key may hold open at once; one more is answered 429", ge=1
    )
    body_timeout_s: float = setting(
        30.0, "a request body that brings nothing for this long before it is complete is answered 408",
        unit="s", gt=0, le=3600,
    )  # fmt: skip
    max_json_bytes: int = setting(
        MiB + 64 * KiB, "size limit of a request body on every route but the uploads, all JSON",
        unit="bytes", ge=KiB, le=2**30,
    )  # fmt: skip
    header_timeout_s: float = setting(
        10.0, "a connection whose request headers are not complete within this long is closed",
        unit="s", ge=0.01, le=3600,
    )  # fmt: skip
    body_min_rate_bytes_s: float = setting(
        1024.0, "after --body-rate-grace-s, a request body slower than this on average is answered 408 "
        "(0: no minimum)", unit="B/s", ge=0, le=2**30,
    )  # fmt: skip
    body_rate_grace_s: float = setting(
        5.0, "time a request body has before its minimum rate applies", unit="s", ge=0, le=3600
    )
    body_total_timeout_s: float = setting(
        300.0, "a request body not complete within this long is answered 408", unit="s", ge=0.01, le=86400
    )
    max_connections_per_address: int = setting(
        64, "open connections one client address may hold; one more is closed at once (behind a reverse "
        "proxy all clients share its address)", ge=1, le=100_000,
    )  # fmt: skip
    max_queued_jobs_per_key: int = setting(
        20, "jobs one key may have queued or running at once; one more submit is answered 429", ge=1
    )
    max_scheduled_tests_per_key: int = setting(
        100, "scheduled tests one key may have waiting or running at once; one more is answered 429", ge=1
    )
    min_free_bytes: int = setting(
        1024 * MiB, "free disk kept on the data directory's file system: an upload that would leave less "
        "is answered 507", unit="bytes", ge=0,
    )  # fmt: skip
    retain_days: float = setting(
        90.0, "uploaded inputs of finished jobs and sweep recordings older than this are deleted, at start "
        "and every 6 h, each logged; 0 keeps everything", unit="days", ge=0,
    )  # fmt: skip


LIMITS = ServiceLimits()
"""The defaults."""


@dataclass(frozen=True)
class WorkerLimits:
    """The worker process's settings a lane chooses (service.jobs.manager.WorkerSettings and the shared job
    queue take their defaults from here, `serve` its --worker-nice and --job-lease-s)."""

    worker_nice: int = setting(
        5, "nice increment of the worker: the event loop keeps priority over the estimator", ge=0, le=19
    )
    job_lease_s: float = setting(
        30.0,
        "a job's claim in the shared queue lasts this long unless renewed; another instance runs the job "
        "again after it if this one dies",
        unit="s",
        ge=0.5,
        le=3600,
    )


SERVE_UNITS: dict[str, tuple[str, float, type, str]] = {
    "max_upload_bytes": ("MiB", 1 / MiB, float, "mb"),
    "max_json_bytes": ("KiB", 1 / KiB, int, "kb"),
    "min_free_bytes": ("MiB", 1 / MiB, float, "mb"),
}
"""How serve shows a size in another unit than the service's bytes: field -> (unit, scale, option type, the
flag's unit: --max-upload-mb)."""
