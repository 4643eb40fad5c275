"""The probes (issue 31, item 3): GET /healthz and /readyz answer without a key, read no body and look up no
key, and /readyz names the check that failed: the database, the worker, the bench's devices; it also says
whether the compiled kernel is built (never a failure)."""

from __future__ import annotations

import asyncio
import dataclasses
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from live_server import LiveServer

from estimator import simulation_kernel
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.key_gate import EXEMPT_PATHS, OPEN, KeyGate
from service.api.routes.health import database_check, kernel_check
from service.store.database import Database

ROOT = Path(__file__).resolve().parents[2]
OPERATOR = "operator-key-0123456789"
KEYS = KeyRing({OPERATOR: Role.OPERATOR})


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("probes"), keys=KEYS, simulated=True)
    with LiveServer(create_app(settings)) as live:
        yield live


@pytest.mark.parametrize("headers", [{}, {"Authorization": "Bearer not-a-key-of-this-service"}])
def test_the_probes_answer_anyone(server: LiveServer, headers: dict[str, str]) -> None:
    assert httpx.get(f"{server.url}/healthz", headers=headers).json() == {"status": "ok"}
    ready = httpx.get(f"{server.url}/readyz", headers=headers)
    assert ready.status_code == 200, ready.text
    body = ready.json()
    assert body["status"] == "ready" and body["failed"] == []
    assert set(body["checks"]) == {"database", "worker", "devices", "kernel"}
    assert all(check["ok"] for check in body["checks"].values())
    assert "simulated bench" in body["checks"]["devices"]["detail"]


def test_the_gate_exempts_the_probes_by_path_before_its_route_table() -> None:
    gate = KeyGate(app=None, routes=[], keys=KEYS)  # type: ignore[arg-type]
    for path in ("/healthz", "/readyz"):
        assert path in EXEMPT_PATHS
        assert gate.policy({"type": "http", "path": path, "method": "GET"}) is OPEN
    assert gate._table_of == -1  # answered without building the route table


def call_without_a_body(app: Any, path: str) -> tuple[int, bytes]:
    """Call the app (ASGI) with a request that announces a body (under the JSON cap, so that the request
    reaches its route) whose reading fails the test."""

    async def receive() -> dict[str, Any]:
        raise AssertionError(f"{path} read the request body")

    sent: list[dict[str, Any]] = []

    async def send(message: dict[str, Any]) -> None:
        sent.append(message)

    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "GET",
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "query_string": b"",
        "root_path": "",
        "headers": [(b"host", b"bench"), (b"content-length", b"100000")],
        "client": ("127.0.0.1", 50000),
        "server": ("127.0.0.1", 8000),
    }
    asyncio.run(app(scope, receive, send))
    status = next(m["status"] for m in sent if m["type"] == "http.response.start")
    return status, b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")


@pytest.mark.parametrize("path", ["/healthz", "/readyz"])
def test_a_probe_never_reads_a_body(server: LiveServer, path: str) -> None:
    status, body = call_without_a_body(server.app, path)
    assert status == 200, body


def test_an_unreachable_database_fails_its_check_in_one_line(server: LiveServer, tmp_path: Path) -> None:
    (tmp_path / "db.sqlite3").mkdir()  # a folder where the database file should be: it cannot be opened
    broken = Database(f"sqlite:///{tmp_path / 'db.sqlite3'}")
    services = dataclasses.replace(server.app.state.services, database=broken)
    try:
        check = asyncio.run(database_check(services))
    finally:
        broken.dispose()
    assert not check.ok
    assert "db.sqlite3" in check.detail and "OperationalError" in check.detail and "\n" not in check.detail


def closed_port() -> int:
    """A loopback port nothing listens on (bound, then closed)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def test_a_drive_unreachable_at_start_up_makes_the_service_not_ready(tmp_path: Path) -> None:
    example = (ROOT / "deploy" / "bench.example.toml").read_text()
    config = tmp_path / "bench.toml"
    config.write_text(example.replace("192.168.0.20:502", f"127.0.0.1:{closed_port()}"))
    settings = ServiceSettings(data_dir=tmp_path / "data", keys=KEYS, bench_config=config)
    with LiveServer(create_app(settings)) as live:
        assert httpx.get(f"{live.url}/healthz").status_code == 200  # the process answers all the same
        ready = httpx.get(f"{live.url}/readyz")
    assert ready.status_code == 503
    body = ready.json()
    assert body["status"] == "not ready" and body["failed"] == ["devices"]
    assert "could not command the drive 'plate-drive'" in body["checks"]["devices"]["detail"]
    assert body["checks"]["database"]["ok"] and body["checks"]["worker"]["ok"]


def test_readiness_says_whether_the_compiled_kernel_is_built(monkeypatch: pytest.MonkeyPatch) -> None:
    """A stale or missing extension is no failure (numba runs the kernel) but the detail says so, with the
    command that builds it; neither case imports numba or loads the extension."""
    monkeypatch.setattr(simulation_kernel, "extension_name", lambda: "_simulation_kernel_aot_" + "0" * 8)
    missing = kernel_check()
    assert missing.ok and "not built for this version" in missing.detail
    assert "python -m service.kernel_build" in missing.detail
    # found: a module of that name exists in the estimator package
    monkeypatch.setattr(simulation_kernel, "extension_name", lambda: "simulation_kernel")
    assert kernel_check() == dataclasses.replace(missing, detail="compiled ahead of time (simulation_kernel)")
