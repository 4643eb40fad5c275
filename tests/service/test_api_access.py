"""Access control: the keys file, and every endpoint refusing anonymous callers (401) and control
endpoints refusing viewers (403), on the real server."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from live_server import LiveServer

from service.access import MIN_KEY_LENGTH, KeyRing, KeysFileError, Role, load_keys
from service.api import ServiceSettings, create_app

VIEWER, OPERATOR, ADMIN = "viewer-key-0123456789", "operator-key-0123456789", "admin-key-0123456789"
RING = KeyRing({VIEWER: Role.VIEWER, OPERATOR: Role.OPERATOR, ADMIN: Role.ADMIN})

CONTROL = [("POST", "/api/v1/jobs"), ("POST", "/api/v1/jobs/1/cancel")]
READ = [
    ("GET", "/api/v1/status"),
    ("GET", "/api/v1/jobs"),
    ("GET", "/api/v1/jobs/1"),
    ("GET", "/api/v1/jobs/1/events"),
    ("GET", "/api/v1/jobs/1/plot.png"),
    ("GET", "/api/v1/jobs/1/plot.svg"),
]


def bearer(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("access"), keys=RING)
    with LiveServer(create_app(settings)) as server, httpx.Client(base_url=server.url, timeout=30) as c:
        yield c


def test_keys_file_gives_each_key_its_role(tmp_path: Path) -> None:
    path = tmp_path / "keys.toml"
    path.write_text(f'viewer = ["{VIEWER}"]\noperator = ["{OPERATOR}", "second-operator-key-000"]\n')
    ring = load_keys(path)
    assert len(ring) == 3
    assert ring.lookup(VIEWER).role is Role.VIEWER
    assert ring.lookup("second-operator-key-000").role is Role.OPERATOR
    assert ring.lookup(ADMIN) is None
    assert ring.lookup(OPERATOR).key_id != ring.lookup(VIEWER).key_id


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("operator = [", "not valid TOML"),
        ('superuser = ["' + "k" * 20 + '"]', "unknown role 'superuser'"),
        ('operator = "' + "k" * 20 + '"', "must be a list of keys"),
        ('operator = ["short"]', f"shorter than {MIN_KEY_LENGTH} characters"),
        ('viewer = ["' + "k" * 20 + '"]\nadmin = ["' + "k" * 20 + '"]', "the same key is listed twice"),
        ("", "no keys"),
    ],
)
def test_bad_keys_file_is_one_line_naming_the_file(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "keys.toml"
    path.write_text(text)
    with pytest.raises(KeysFileError) as caught:
        load_keys(path)
    assert str(caught.value).startswith(f"{path}: ")
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_generated_key_is_an_operator_key() -> None:
    ring, key = KeyRing.generated()
    assert len(key) >= MIN_KEY_LENGTH
    assert ring.lookup(key).role is Role.OPERATOR
    assert KeyRing.generated()[1] != key


@pytest.mark.parametrize(("method", "path"), CONTROL + READ)
def test_anonymous_calls_are_refused_with_401(client: httpx.Client, method: str, path: str) -> None:
    response = client.request(method, path)
    assert response.status_code == 401
    assert response.json()["error"]["code"] == "unauthorized"
    assert response.headers["www-authenticate"] == "Bearer"


@pytest.mark.parametrize(
    "header",
    [
        bearer("not-a-key-of-this-service"),
        {"Authorization": f"Basic {OPERATOR}"},
        {"Authorization": "Bearer"},
    ],
)
def test_unknown_keys_and_other_schemes_are_refused(client: httpx.Client, header: dict[str, str]) -> None:
    assert client.post("/api/v1/jobs", headers=header).status_code == 401


@pytest.mark.parametrize(("method", "path"), CONTROL)
def test_viewer_calls_to_control_endpoints_are_refused_with_403(
    client: httpx.Client, method: str, path: str
) -> None:
    response = client.request(method, path, headers=bearer(VIEWER))
    assert response.status_code == 403
    error = response.json()["error"]
    assert error["code"] == "forbidden"
    assert "operator role" in error["message"] and "viewer" in error["message"]


def test_viewer_reads_and_operator_and_admin_get_past_the_role_check(client: httpx.Client) -> None:
    assert client.get("/api/v1/status", headers=bearer(VIEWER)).status_code == 200
    assert client.get("/api/v1/jobs", headers=bearer(VIEWER)).status_code == 200
    for key in (OPERATOR, ADMIN):  # admitted: what refuses them now is the missing upload (422)
        response = client.post("/api/v1/jobs", headers=bearer(key))
        assert response.status_code == 422, response.text
        assert client.post("/api/v1/jobs/999/cancel", headers=bearer(key)).status_code == 404


def serve(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "service.cli.serve", *args], capture_output=True, text=True, timeout=120
    )


def test_serve_refuses_a_non_loopback_host_without_keys(tmp_path: Path) -> None:
    done = serve("--host", "0.0.0.0", "--data", str(tmp_path))
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "shockbench serve: error: --host 0.0.0.0 is not a loopback address: serving beyond this machine "
        "needs --keys"
    ]


def test_serve_with_a_bad_keys_file_says_so_in_one_line(tmp_path: Path) -> None:
    keys = tmp_path / "keys.toml"
    keys.write_text('operator = ["short"]\n')
    done = serve("--keys", str(keys), "--data", str(tmp_path))
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1
    assert str(keys) in done.stderr and "Traceback" not in done.stderr
