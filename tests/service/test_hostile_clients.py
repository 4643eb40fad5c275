"""Hostile clients (issue 30), each case over raw sockets or httpx against the real uvicorn server with the
in-process simulated bench: the key checked before the body is read, body caps per route, deadlines for
the headers and the body, a cap on the connections of one client address, and the security headers on
every kind of response.

Deadlines are short here (a fraction of a second) so that the tests stay fast; a test waits for a
server-side deadline by blocking on the socket until the server answers or closes (bounded by IO_BOUND_S),
and asserts what happened, never how long it took."""

from __future__ import annotations

import base64
import contextlib
import hashlib
import re
import resource
import selectors
import socket
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
from live_server import LiveServer, add_broken_route

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.security_headers import PAGE_POLICY

OPERATOR = "operator-key-0123456789"
VIEWER = "viewer-key-0123456789abc"
AUTH = {"Authorization": f"Bearer {OPERATOR}"}
KEYS = {OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER}
MAX_JSON_BYTES = 8 * 1024
MAX_UPLOAD_BYTES = 256 * 1024
PER_ADDRESS = 50
HEADER_TIMEOUT_S = 0.3
IO_BOUND_S = 30.0
"""Longest wait on a socket: a bound for a hang, never a timing assertion."""
FORTY_MB = 40_000_000


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """Small body caps and a per-address cap; the default deadlines (headers: 10 s)."""
    settings = ServiceSettings(
        data_dir=tmp_path_factory.mktemp("hostile"),
        keys=KeyRing(KEYS),
        simulated=True,
        max_json_bytes=MAX_JSON_BYTES,
        max_upload_bytes=MAX_UPLOAD_BYTES,
        max_connections_per_address=PER_ADDRESS,
    )
    app = create_app(settings)

    add_broken_route(app)
    with LiveServer(app) as live:
        yield live


@pytest.fixture(scope="module")
def strict(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """Deadlines of a fraction of a second: headers 0.3 s; a body at least 1000 bytes/s after 0.2 s,
    whole within 0.6 s."""
    settings = ServiceSettings(
        data_dir=tmp_path_factory.mktemp("strict"),
        keys=KeyRing(KEYS),
        header_timeout_s=HEADER_TIMEOUT_S,
        body_min_rate_bytes_s=1000,
        body_rate_grace_s=0.2,
        body_total_timeout_s=0.6,
    )
    with LiveServer(create_app(settings)) as live:
        yield live


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as c:
        yield c


def address(server: LiveServer) -> tuple[str, int]:
    host, port = server.url.removeprefix("http://").split(":")
    return host, int(port)


@dataclass
class Answer:
    status: int
    headers: dict[str, str]
    body: bytes
    closed: bool
    """The server closed the connection after the answer."""


def read_answer(sock: socket.socket) -> Answer:
    """One HTTP/1.1 response from `sock` (Content-Length framed), then whether the server closed the
    connection: blocks until it did or IO_BOUND_S passed (then: not closed)."""
    sock.settimeout(IO_BOUND_S)
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(65536)
        assert chunk, f"the server closed without an answer (got {data!r})"
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    headers = {k.strip().lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:])}
    length = int(headers.get("content-length", "0"))
    while len(body) < length:
        chunk = sock.recv(65536)
        assert chunk, "the server closed in the middle of its answer"
        body += chunk
    return Answer(int(lines[0].split()[1]), headers, body, closed_by_server(sock))


def closed_by_server(sock: socket.socket) -> bool:
    sock.settimeout(IO_BOUND_S)
    try:
        return sock.recv(1) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def request_head(method: str, path: str, *headers: str, length: int | None = None) -> bytes:
    lines = [f"{method} {path} HTTP/1.1", "Host: bench", *headers]
    if length is not None:
        lines.append(f"Content-Length: {length}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def exchange(server: LiveServer, data: bytes) -> Answer:
    with socket.create_connection(address(server), timeout=IO_BOUND_S) as sock:
        sock.sendall(data)
        return read_answer(sock)


# ---- the key before the body ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("path", "content_type"),
    [
        ("/api/v1/jobs", "multipart/form-data; boundary=XX"),
        ("/api/v1/sweeps", "application/json"),
        ("/api/v1/emergency-stop", "application/json"),
    ],
)
@pytest.mark.parametrize("key", [None, "not-a-key-of-this-service"])
def test_an_anonymous_40_MB_post_is_refused_401_after_64_KiB_and_the_connection_closed(
    server: LiveServer, path: str, content_type: str, key: str | None
) -> None:
    headers = [f"Content-Type: {content_type}"] + ([f"Authorization: Bearer {key}"] if key else [])
    with socket.create_connection(address(server), timeout=IO_BOUND_S) as sock:
        sock.sendall(request_head("POST", path, *headers, length=FORTY_MB) + b"x" * 65536)
        answer = read_answer(sock)  # 64 KiB of 40 MB sent: the answer comes now, not after 40 MB
    assert answer.status == 401, answer
    assert answer.headers["connection"] == "close"
    assert answer.headers["www-authenticate"] == "Bearer"
    assert answer.closed  # the rest of the body is never read
    message = httpx.Response(401, content=answer.body).json()["error"]["message"]
    assert message == ("unknown key" if key else "this needs a key: send 'Authorization: Bearer KEY'")


def test_roles_are_still_checked_by_the_routes(server: LiveServer) -> None:
    viewer = {"Authorization": f"Bearer {VIEWER}"}
    refused = httpx.post(f"{server.url}/api/v1/emergency-stop", headers=viewer)
    assert refused.status_code == 403 and "operator role" in refused.json()["error"]["message"]
    assert httpx.get(f"{server.url}/api/v1/status", headers=viewer).status_code == 200


@pytest.mark.parametrize("path", ["/", "/web/app.js", "/docs", "/api/v1/openapi.json"])
def test_the_page_the_docs_and_the_schema_need_no_key(server: LiveServer, path: str) -> None:
    assert httpx.get(server.url + path).status_code == 200


def test_an_unread_body_closes_the_connection_behind_a_404(server: LiveServer) -> None:
    """Under the cap, so the 404 is the answer; the body half sent is not read to its end."""
    head = request_head("POST", "/api/v1/no-such-thing", f"Authorization: Bearer {OPERATOR}", length=8000)
    answer = exchange(server, head + b"x" * 100)
    assert answer.status == 404
    assert answer.headers["connection"] == "close" and answer.closed


# ---- body caps -----------------------------------------------------------------------------------------


def test_a_json_body_over_the_json_limit_is_413_before_it_is_read(server: LiveServer) -> None:
    head = request_head(
        "POST",
        "/api/v1/sweeps",
        f"Authorization: Bearer {OPERATOR}",
        "Content-Type: application/json",
        length=MAX_JSON_BYTES + 1,
    )
    answer = exchange(server, head)  # no body sent at all
    assert answer.status == 413 and answer.closed
    error = httpx.Response(413, content=answer.body).json()["error"]
    assert error["code"] == "payload_too_large"
    assert (
        error["message"]
        == f"request body larger than the JSON body limit of 0.00781 MiB ({MAX_JSON_BYTES} bytes)"
    )


def test_a_chunked_json_body_is_counted_and_cut_at_the_json_limit(client: httpx.Client) -> None:
    def chunks() -> Iterator[bytes]:
        yield b'{"vehicle_toml": "'
        for _ in range(2 * MAX_JSON_BYTES // 1024):
            yield b"x" * 1024

    response = client.post("/api/v1/sweeps", content=chunks(), headers={"Content-Type": "application/json"})
    assert response.status_code == 413, response.text
    assert "JSON body limit" in response.json()["error"]["message"]


def test_the_upload_routes_take_bodies_up_to_the_upload_limit(client: httpx.Client) -> None:
    """A multipart body above the JSON limit is parsed (here: refused for its content, 422); above the
    upload limit it is 413 naming the upload limit."""
    recording = b"t,x_s,x_t,x_r\n" + b"not a number,1,2,3\n" * (2 * MAX_JSON_BYTES // 19)
    files = {"recording": ("r.csv", recording), "vehicle": ("v.toml", b"[vehicle]\n")}
    parsed = client.post("/api/v1/jobs", files=files)
    assert parsed.status_code == 422, parsed.text
    files["recording"] = ("r.csv", b"x" * (MAX_UPLOAD_BYTES + 1))
    too_large = client.post("/api/v1/jobs", files=files)
    assert too_large.status_code == 413
    assert "upload limit of 0.25 MiB" in too_large.json()["error"]["message"]


# ---- deadlines -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "sent",
    [b"", b"GET /api/v1/status HTTP/1.1\r\nHost: bench\r\nAuthorization: Bear"],
    ids=["nothing", "partial headers"],
)
def test_a_connection_without_complete_headers_is_closed_at_the_header_deadline(
    strict: LiveServer, sent: bytes
) -> None:
    with socket.create_connection(address(strict), timeout=IO_BOUND_S) as sock:
        sock.sendall(sent)
        assert closed_by_server(sock)  # blocks until the server's header deadline closes it


def test_the_next_request_on_a_kept_connection_has_the_header_deadline_too(strict: LiveServer) -> None:
    with socket.create_connection(address(strict), timeout=IO_BOUND_S) as sock:
        sock.sendall(request_head("GET", "/api/v1/openapi.json"))
        sock.settimeout(IO_BOUND_S)
        data = b""
        while b"\r\n\r\n" not in data:
            data += sock.recv(65536)
        assert data.startswith(b"HTTP/1.1 200")
        sock.sendall(request_head("GET", "/", length=0))  # a whole second request is answered
        sock.sendall(b"GET /api/v1/status HTTP/1.1\r\nHo")  # a third never completes its headers
        while chunk := sock.recv(65536):  # the answers, then the close
            data += chunk
    assert data.count(b"HTTP/1.1 200") == 2


def body_answer(server: LiveServer, sent: bytes, declared: int) -> Answer:
    head = request_head(
        "POST",
        "/api/v1/sweeps",
        f"Authorization: Bearer {OPERATOR}",
        "Content-Type: application/json",
        length=declared,
    )
    return exchange(server, head + sent)


def test_a_trickling_body_is_answered_408_below_the_minimum_rate(strict: LiveServer) -> None:
    """One byte, then nothing: after the 0.2 s grace the body is under 1000 bytes/s long before the
    30 s pause limit or the 0.6 s total. The headers were complete: the header deadline cuts nothing."""
    answer = body_answer(strict, b"{", 4000)
    assert answer.status == 408 and answer.closed
    assert answer.headers["connection"] == "close"
    error = httpx.Response(408, content=answer.body).json()["error"]
    assert error["code"] == "request_timeout"
    assert error["message"].startswith("the request body arrived too slowly: 1 bytes in ")
    assert "under the minimum of 1000 bytes/s after the first 0.2 s" in error["message"]
    assert answer.headers["content-security-policy"] == PAGE_POLICY  # a 408 carries them too
    assert all(answer.headers[header] == value for header, value in COMMON.items())


def test_a_body_over_its_total_deadline_is_answered_408(strict: LiveServer) -> None:
    """2000 bytes at once keep the minimum rate until 2.2 s; the total of 0.6 s comes first."""
    answer = body_answer(strict, b"{" + b" " * 1999, 4000)
    assert answer.status == 408 and answer.closed
    message = httpx.Response(408, content=answer.body).json()["error"]["message"]
    assert message == "the request body took longer than the 0.6 s allowed for a whole body"


def test_a_prompt_body_meets_every_deadline(strict: LiveServer) -> None:
    body = b'{"duration_s": 2}'
    answer = body_answer(strict, body, len(body))
    assert answer.status == 422  # read and checked: the vehicle file is missing
    assert b"vehicle_toml" in answer.body


# ---- connections per address ---------------------------------------------------------------------------


def test_the_operator_is_served_while_500_half_sent_connections_come_from_another_address(
    server: LiveServer,
) -> None:
    """500 connections from 127.0.0.2, each with half its headers sent: the server keeps PER_ADDRESS of
    them (until their header deadline, 10 s) and closes the others at once; the operator on 127.0.0.1
    reads the status and stops the bench meanwhile."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < 2048:
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(2048, hard), hard))
    attackers: list[socket.socket] = []
    try:
        for _ in range(500):
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            sock.bind(("127.0.0.2", 0))
            sock.settimeout(IO_BOUND_S)
            sock.connect(address(server))
            with contextlib.suppress(BrokenPipeError, ConnectionResetError):  # closed already
                sock.sendall(b"POST /api/v1/jobs HTTP/1.1\r\nHost: bench\r\nContent-Le")
            attackers.append(sock)
        closed = closed_among(attackers, expected=500 - PER_ADDRESS)
        assert len(closed) == 500 - PER_ADDRESS
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=IO_BOUND_S) as operator:
            assert operator.get("/api/v1/status").status_code == 200
            stop = operator.post("/api/v1/emergency-stop")
            assert stop.status_code == 200, stop.text
        open_ones = [s for s in attackers if s not in closed]
        for sock in open_ones:  # still held by the server: nothing to read, no end of stream
            sock.setblocking(False)
            with pytest.raises(BlockingIOError):
                sock.recv(1)
    finally:
        for sock in attackers:
            sock.close()


def closed_among(sockets: list[socket.socket], expected: int) -> set[socket.socket]:
    """The sockets the server has closed, waiting (bounded by IO_BOUND_S) until `expected` of them are."""
    closed: set[socket.socket] = set()
    with selectors.DefaultSelector() as selector:
        for sock in sockets:
            selector.register(sock, selectors.EVENT_READ)
        while len(closed) < expected:
            ready = selector.select(IO_BOUND_S)
            if not ready:
                break
            for key, _ in ready:
                sock = key.fileobj
                assert isinstance(sock, socket.socket)
                selector.unregister(sock)
                sock.setblocking(False)
                try:
                    ended = sock.recv(1) == b""
                except ConnectionResetError:
                    ended = True
                assert ended, "a half-sent connection got an answer"
                closed.add(sock)
    return closed


# ---- security headers ----------------------------------------------------------------------------------

COMMON = {
    "x-content-type-options": "nosniff",
    "referrer-policy": "no-referrer",
    "x-frame-options": "DENY",
}


def every_kind_of_response(server: LiveServer) -> dict[str, httpx.Response]:
    url = server.url
    viewer = {"Authorization": f"Bearer {VIEWER}"}
    with (
        httpx.Client(base_url=url, timeout=60) as anonymous,
        httpx.Client(base_url=url, headers=AUTH, timeout=60) as keyed,
        httpx.Client(base_url=url, headers=viewer, timeout=60) as viewing,
    ):
        return {
            "page": anonymous.get("/"),
            "page file": anonymous.get("/web/app.js"),
            "schema": anonymous.get("/api/v1/openapi.json"),
            "api 200": keyed.get("/api/v1/status"),
            "401 of the gate": anonymous.post("/api/v1/sweeps", json={}),
            "403": viewing.post("/api/v1/emergency-stop"),
            "404": keyed.get("/api/v1/no-such-thing"),
            "405": keyed.put("/api/v1/status"),
            "413": keyed.post("/api/v1/sweeps", content=b"x" * (MAX_JSON_BYTES + 1)),
            "422": keyed.post("/api/v1/sweeps", json={}),
            "500": keyed.get("/api/v1/broken"),
            "options 204": keyed.options("/api/v1/jobs"),
        }


def test_every_kind_of_response_carries_the_security_headers(server: LiveServer) -> None:
    responses = every_kind_of_response(server)
    statuses = {name: response.status_code for name, response in responses.items()}
    assert statuses == {
        "page": 200,
        "page file": 200,
        "schema": 200,
        "api 200": 200,
        "401 of the gate": 401,
        "403": 403,
        "404": 404,
        "405": 405,
        "413": 413,
        "422": 422,
        "500": 500,
        "options 204": 204,
    }
    for name, response in responses.items():
        for header, value in COMMON.items():
            assert response.headers.get(header) == value, (name, header)
        assert response.headers.get("content-security-policy") == PAGE_POLICY, name


def test_the_page_policy_allows_only_the_services_own_scripts_and_no_frames() -> None:
    directives = dict(d.split(" ", 1) for d in PAGE_POLICY.split("; "))
    assert directives["script-src"] == "'self'" and directives["style-src"] == "'self'"
    assert directives["frame-ancestors"] == "'none'"
    assert "unsafe" not in PAGE_POLICY


def test_the_page_has_no_inline_script_or_style() -> None:
    page = (Path(__file__).resolve().parents[2] / "service" / "web" / "index.html").read_text()
    assert re.findall(r"<script(?![^>]*\bsrc=)", page) == []
    assert "<style" not in page and " style=" not in page


def test_the_docs_page_allows_its_own_swagger_ui_and_inline_script_by_hash(server: LiveServer) -> None:
    docs = httpx.get(f"{server.url}/docs")
    assert docs.status_code == 200
    policy = docs.headers["content-security-policy"]
    for header, value in COMMON.items():
        assert docs.headers[header] == value
    directives = dict(d.split(" ", 1) for d in policy.split("; "))
    inline = re.findall(r"<script>(.*?)</script>", docs.text, flags=re.DOTALL)
    assert len(inline) == 1
    digest = base64.b64encode(hashlib.sha256(inline[0].encode()).digest()).decode()
    assert directives["script-src"] == f"'self' 'sha256-{digest}'"
    # what the policy allows is what the page loads: the package's own copy, no CDN (offline lanes)
    assert 'src="/docs/assets/swagger-ui-bundle.js"' in docs.text and "https://" not in docs.text
    assert directives["frame-ancestors"] == "'none'" and directives["connect-src"] == "'self'"
    assert "/api/v1/openapi.json" in inline[0]
