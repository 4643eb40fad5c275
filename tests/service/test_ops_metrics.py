"""GET /metrics (issue 31, item 3): Prometheus' text format, read back with prometheus-client's own parser;
admin-only by default, any key or anyone by the setting; a sweep, its identification job and a worker's
death counted; the sync backlog of a lane's local store; each app its own registry."""

from __future__ import annotations

import os
import re
import signal
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from live_server import LiveServer, wait_for_status, wait_until
from prometheus_client.parser import text_string_to_metric_families

from daq.formats.recording_file import read_recording_file
from daq.formats.vehicle_file import format_vehicle
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.store.models import JobKind, JobStatus, SweepStatus
from simulators.vehicle_sim import default_quarter_car

VIEWER, ADMIN = "viewer-key-0123456789", "admin-key-0123456789ab"
KEYS = KeyRing({VIEWER: Role.VIEWER, ADMIN: Role.ADMIN})
SWEEP = {
    "start_Hz": 0,
    "stop_Hz": 20,
    "amplitude_m": 0.004,
    "duration_s": 12,
    "settle_s": 1,
    "vehicle_toml": format_vehicle(default_quarter_car().known),
}
"""A sweep whose identification finds the curve (tests/service/test_api_sweeps.py)."""
Samples = dict[tuple[str, frozenset[tuple[str, str]]], float]


def auth(key: str | None) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"} if key else {}


def scrape(url: str, key: str | None) -> Samples:
    """GET /metrics, parsed: (sample name, labels) -> value."""
    answer = httpx.get(f"{url}/metrics", headers=auth(key), timeout=30)
    assert answer.status_code == 200, answer.text
    assert answer.headers["content-type"].startswith("text/plain; version=")
    return {
        (sample.name, frozenset(sample.labels.items())): sample.value
        for family in text_string_to_metric_families(answer.text)
        for sample in family.samples
    }


def value(samples: Samples, name: str, **labels: str) -> float:
    return samples[(name, frozenset(labels.items()))]


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """The simulated bench, metrics at their default access (admin)."""
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("metrics"), keys=KEYS, simulated=True)
    with LiveServer(create_app(settings)) as live:
        yield live


@pytest.mark.parametrize(("key", "status"), [(None, 401), ("not-a-key-of-this-bench", 401), (VIEWER, 403)])
def test_by_default_only_an_admin_reads_the_metrics(bench: LiveServer, key: str | None, status: int) -> None:
    assert httpx.get(f"{bench.url}/metrics", headers=auth(key)).status_code == status
    assert httpx.get(f"{bench.url}/metrics", headers=auth(ADMIN)).status_code == 200


def test_a_sweep_and_its_identification_are_counted(bench: LiveServer) -> None:
    before = scrape(bench.url, ADMIN)
    assert value(before, "shockbench_sweeps", state="complete") == 0
    assert value(before, "shockbench_jobs", kind="identify", state="succeeded") == 0
    assert value(before, "shockbench_acquisition_rows_total") == 0
    with bench.client(ADMIN) as client:
        started = client.post("/api/v1/sweeps", json=SWEEP)
        assert started.status_code == 201, started.text
        sweep = wait_for_status(client, started.headers["location"], "complete", "failed", "aborted")
        assert sweep["status"] == "complete", sweep
        submitted = client.post(sweep["links"]["jobs"], json={})
        assert submitted.status_code == 201, submitted.text
        job = wait_for_status(client, submitted.headers["location"], "succeeded", "failed", timeout_s=300)
        assert job["status"] == "succeeded", job["error"]

    after = scrape(bench.url, ADMIN)
    assert value(after, "shockbench_sweeps", state="complete") == 1
    assert value(after, "shockbench_jobs", kind="identify", state="succeeded") == 1
    for state in (s.value for s in SweepStatus if s is not SweepStatus.COMPLETE):
        assert value(after, "shockbench_sweeps", state=state) == 0
    for kind in JobKind:
        for state in JobStatus:
            expected = 1 if (kind, state) == (JobKind.IDENTIFY, JobStatus.SUCCEEDED) else 0
            assert value(after, "shockbench_jobs", kind=kind.value, state=state.value) == expected
    runs = {"kind": "identify", "outcome": "succeeded"}
    assert value(after, "shockbench_job_duration_seconds_count", **runs) == 1
    assert value(after, "shockbench_job_duration_seconds_sum", **runs) > 0
    assert value(after, "shockbench_job_duration_seconds_bucket", le="+Inf", **runs) == 1
    record = bench.app.state.services.sweeps.get(sweep["id"])
    rows = read_recording_file(record.recording_path).time_s.size
    assert value(after, "shockbench_acquisition_rows_total") == rows
    assert value(after, "shockbench_acquisition_gap_rows_total") == 0
    for channel in ("x_s", "x_t", "x_r"):
        assert value(after, "shockbench_acquisition_samples_total", channel=channel) >= rows
        assert value(after, "shockbench_acquisition_lost_samples_total", channel=channel) == 0
    assert value(after, "shockbench_job_queue_depth") == 0
    assert value(after, "shockbench_bench_busy") == 0
    assert value(after, "shockbench_database_up") == 1
    assert value(after, "shockbench_worker_up") == 1
    assert value(after, "process_resident_memory_bytes") > 0  # the process collector of the same registry


def test_the_operations_guide_names_every_metric(bench: LiveServer) -> None:
    guide = (Path(__file__).resolve().parents[2] / "docs" / "operations.md").read_text(encoding="utf-8")
    names = {
        re.sub(r"_(bucket|count|sum)$", "", name)
        for name, _ in scrape(bench.url, ADMIN)
        if name.startswith("shockbench_") and not name.endswith("_created")
    }
    assert len(names) >= 14
    assert sorted(name for name in names if f"`{name}`" not in guide) == []


def test_a_worker_that_dies_is_counted_as_a_restart(bench: LiveServer) -> None:
    before = value(scrape(bench.url, ADMIN), "shockbench_worker_restarts_total")
    manager = bench.app.state.services.manager
    victim = manager.status().worker_pid
    os.kill(victim, signal.SIGKILL)

    def replaced() -> Samples | None:
        """The restart counted and the new worker up (the count goes up just before it is started)."""
        now = scrape(bench.url, ADMIN)
        up = value(now, "shockbench_worker_up") == 1 and manager.status().worker_pid != victim
        return now if up and value(now, "shockbench_worker_restarts_total") == before + 1 else None

    wait_until(replaced, 60, "worker restart counted and the new worker up")


def test_any_key_reads_them_when_set_so_and_a_local_stores_sync_backlog_shows(tmp_path: Path) -> None:
    central = f"sqlite:///{tmp_path / 'central.sqlite3'}"
    settings = ServiceSettings(
        data_dir=tmp_path / "lane", keys=KEYS, database_url=central, local_store=True, metrics_access="key"
    )
    with LiveServer(create_app(settings)) as live:
        assert httpx.get(f"{live.url}/metrics").status_code == 401

        def synced() -> Samples | None:
            now = scrape(live.url, VIEWER)
            return now if value(now, "shockbench_sync_reachable") == 1 else None

        samples = wait_until(synced, 60, "a sync round that reached the central database")
    assert value(samples, "shockbench_sync_backlog") == 0
    assert value(samples, "shockbench_sync_oldest_pending_age_seconds") == 0
    assert value(samples, "shockbench_sync_pushed_total") == 0


def test_open_metrics_need_no_key_and_a_service_without_bench_has_no_bench_series(tmp_path: Path) -> None:
    settings = ServiceSettings(data_dir=tmp_path, keys=KEYS, lane="north", metrics_access="open")
    with LiveServer(create_app(settings)) as live:
        samples = scrape(live.url, None)
    assert value(samples, "shockbench_build_info", lane="north", version=live.app.version) == 1
    assert not any(name.startswith(("shockbench_bench_", "shockbench_sync_")) for name, _ in samples)


def test_each_app_has_its_own_registry(tmp_path: Path) -> None:
    """Two apps in one process: no duplicated series, and what one observes the other does not see."""
    first = create_app(ServiceSettings(data_dir=tmp_path / "a", keys=KEYS))
    second = create_app(ServiceSettings(data_dir=tmp_path / "b", keys=KEYS))
    assert first.state.metrics.registry is not second.state.metrics.registry
    first.state.metrics.job_finished("identify", "succeeded", 3.0)
    runs = {"kind": "identify", "outcome": "succeeded"}
    count = "shockbench_job_duration_seconds_count"
    assert first.state.metrics.registry.get_sample_value(count, runs) == 1
    assert second.state.metrics.registry.get_sample_value(count, runs) is None


def test_an_unknown_access_setting_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="metrics_access must be one of admin, key, open"):
        create_app(ServiceSettings(data_dir=tmp_path, keys=KEYS, metrics_access="public"))  # type: ignore[arg-type]
