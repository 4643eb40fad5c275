"""Quotas (issue 30, item 3): one key's queued and running jobs are limited (429 with Retry-After, the
check in the inserting transaction so concurrent submits never overshoot, on SQLite and PostgreSQL), and an
upload is refused with 507 before anything of it is stored when the data directory is short of disk.
Retention: tests/service/test_retention.py."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import pytest
from live_server import LiveServer, SimulatedInputs, wait_for_status

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.quotas import RETRY_AFTER_S
from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.models import ScheduleStatus
from service.store.quota import KeyQuota, QuotaExceededError
from service.store.schedules import ScheduleStore

OPERATOR = "operator-key-0123456789"
OTHER = "other-operator-key-0123456789"
LIMIT = 2
MIN_FREE = 100 * 2**20
LONG_JOB = {"solver": "de", "generations": "200000"}
"""Runs for minutes: the key's jobs stay queued or running until cancelled."""


# ---- the store: the count and the insert in one transaction ---------------------------------------------


def files(tmp: Path) -> JobFiles:
    return JobFiles(tmp / "r.csv", tmp / "v.toml", tmp)


def test_the_quota_counts_the_keys_queued_and_running_jobs_only(database: Database, tmp_path: Path) -> None:
    store = JobStore(database, lane="L")
    quota = KeyQuota("key-a", 2)
    first = store.create("identify", {}, lambda _i: files(tmp_path), submitted_by="key-a", quota=quota)
    store.create("identify", {}, lambda _i: files(tmp_path), submitted_by="key-a", quota=quota)
    assert store.mark_running(first.id)
    with pytest.raises(QuotaExceededError, match=r"2 jobs queued or running, the most allowed \(2\)"):
        store.create("identify", {}, lambda _i: files(tmp_path), submitted_by="key-a", quota=quota)
    with pytest.raises(QuotaExceededError):
        store.check_quota(quota)  # the look before an upload is copied says the same
    assert store.list_jobs()[1] == 2  # the refused job was rolled back
    # another key is not held up, nor is a job the service queues itself (no quota)
    store.create("identify", {}, lambda _i: files(tmp_path), submitted_by="key-b", quota=KeyQuota("key-b", 2))
    store.create("identify", {}, lambda _i: files(tmp_path), submitted_by="key-a")
    assert store.unfinished_count("key-a") == 3
    # a job that ends makes room
    assert store.succeed(first.id, {"ok": True}, {}, None)
    assert store.cancel(store.list_jobs()[0][0].id)
    again = store.create("identify", {}, lambda _i: files(tmp_path), submitted_by="key-a", quota=quota)
    assert again.submitted_by == "key-a" and store.unfinished_count("key-a") == 2


def test_concurrent_submits_of_one_key_never_overshoot(database: Database, tmp_path: Path) -> None:
    """Eight submits of one key at once against a limit of 3: exactly 3 are queued, on either back end."""
    store = JobStore(database, lane="L")
    quota = KeyQuota("busy-key", 3)
    start = threading.Barrier(8)

    def submit(_: int) -> bool:
        start.wait()
        try:
            store.create("identify", {}, lambda _i: files(tmp_path), submitted_by="busy-key", quota=quota)
        except QuotaExceededError:
            return False
        return True

    with ThreadPoolExecutor(8) as pool:
        accepted = list(pool.map(submit, range(8)))
    assert sum(accepted) == 3
    assert store.unfinished_count("busy-key") == 3 and store.list_jobs()[1] == 3


def test_scheduled_tests_have_a_quota_per_key_too(database: Database, tmp_path: Path) -> None:
    store = ScheduleStore(database, lane="L")
    quota = KeyQuota("admin-key", 1)

    def schedule() -> int:
        place = lambda i: tmp_path / f"{i}.toml"  # noqa: E731
        return store.create("bench", {}, {}, None, place, created_by="admin-key", quota=quota).id

    first = schedule()
    with pytest.raises(QuotaExceededError, match="1 scheduled tests waiting or running"):
        schedule()
    assert store.cancel(first)
    assert store.get(schedule()).status is ScheduleStatus.WAITING  # type: ignore[union-attr]


# ---- the API: 429 and 507 -------------------------------------------------------------------------------


DISK = {"free": 10 * 2**30}
"""The free space the service sees (its disk_free_bytes): tests simulate a full disk here."""


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("quotas")


@pytest.fixture(scope="module")
def server(data_dir: Path) -> Iterator[LiveServer]:
    settings = ServiceSettings(
        data_dir=data_dir,
        keys=KeyRing({OPERATOR: Role.OPERATOR, OTHER: Role.OPERATOR}),
        max_queued_jobs_per_key=LIMIT,
        min_free_bytes=MIN_FREE,
        disk_free_bytes=lambda _path: DISK["free"],
    )
    with LiveServer(create_app(settings)) as s:
        yield s


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client(OPERATOR) as c:
        yield c
    with server.client(OPERATOR) as c:  # each test leaves no job of its own behind
        for job in c.get("/api/v1/jobs", params={"limit": 500}).json()["jobs"]:
            if job["status"] in ("queued", "running"):
                c.post(f"/api/v1/jobs/{job['id']}/cancel")
                wait_for_status(c, f"/api/v1/jobs/{job['id']}", "cancelled", "succeeded", "failed")


def submit(client: httpx.Client, inputs: SimulatedInputs, options: dict[str, str]) -> httpx.Response:
    upload = {
        "recording": ("recording.csv", inputs.recording.read_bytes()),
        "vehicle": ("vehicle.toml", inputs.vehicle.read_bytes()),
    }
    return client.post("/api/v1/jobs", files=upload, data=options)


def test_a_key_at_its_job_limit_gets_429_until_one_of_its_jobs_ends(
    server: LiveServer, client: httpx.Client, inputs: SimulatedInputs
) -> None:
    jobs = []
    for _ in range(LIMIT):
        response = submit(client, inputs, LONG_JOB)
        assert response.status_code == 201, response.text
        jobs.append(response.json())
    total = client.get("/api/v1/jobs").json()["total"]

    refused = submit(client, inputs, LONG_JOB)
    assert refused.status_code == 429, refused.text
    assert refused.headers["Retry-After"] == str(RETRY_AFTER_S)
    error = refused.json()["error"]
    assert error["code"] == "too_many_requests"
    assert f"{LIMIT} jobs queued or running, the most allowed ({LIMIT})" in error["message"]
    assert client.get("/api/v1/jobs").json()["total"] == total  # nothing queued

    with server.client(OTHER) as other:  # another key is not held up by this one's jobs
        theirs = submit(other, inputs, LONG_JOB)
        assert theirs.status_code == 201, theirs.text
        assert other.post(f"/api/v1/jobs/{theirs.json()['id']}/cancel").status_code in (200, 202)

    assert client.post(f"/api/v1/jobs/{jobs[-1]['id']}/cancel").status_code in (200, 202)
    wait_for_status(client, f"/api/v1/jobs/{jobs[-1]['id']}", "cancelled")
    again = submit(client, inputs, LONG_JOB)
    assert again.status_code == 201, again.text


def uploads_and_jobs(data_dir: Path) -> tuple[list[Path], list[Path]]:
    return sorted((data_dir / "uploads").iterdir()), sorted((data_dir / "jobs").iterdir())


@pytest.mark.parametrize(
    ("free", "why"),
    [
        (MIN_FREE - 2**20, "has 99.0 MiB free, less than the 100.0 MiB the service keeps free"),
        (MIN_FREE + 2**17, "MiB) would leave less than the 100.0 MiB the service keeps free"),
    ],
)
def test_an_upload_is_refused_with_507_when_the_disk_is_short_and_nothing_is_written(
    client: httpx.Client, inputs: SimulatedInputs, data_dir: Path, free: int, why: str
) -> None:
    before = uploads_and_jobs(data_dir)
    total = client.get("/api/v1/jobs").json()["total"]
    DISK["free"] = free
    try:
        refused = submit(client, inputs, {})
    finally:
        DISK["free"] = 10 * 2**30
    assert refused.status_code == 507, refused.text
    error = refused.json()["error"]
    assert error["code"] == "insufficient_storage" and why in error["message"]
    assert uploads_and_jobs(data_dir) == before and before[0] == []  # nothing stored, not even staged
    assert client.get("/api/v1/jobs").json()["total"] == total

    accepted = submit(client, inputs, {})  # with room again the same upload is taken
    assert accepted.status_code == 201, accepted.text


def test_a_json_request_is_not_held_up_by_a_full_disk(client: httpx.Client) -> None:
    """Only uploads are refused: reading, cancelling, the emergency stop go on with a full disk."""
    DISK["free"] = 0
    try:
        assert client.get("/api/v1/jobs").status_code == 200
        missing: dict[str, Any] = client.post("/api/v1/jobs/999999/cancel").json()
    finally:
        DISK["free"] = 10 * 2**30
    assert missing["error"]["code"] == "not_found"
