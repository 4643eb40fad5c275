"""Input checked at submit: a job that cannot run is refused with 422 naming the field and is never
queued; bodies over the upload limit are refused with 413; errors are typed JSON, never a traceback."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest
from live_server import LiveServer, SimulatedInputs, add_broken_route

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app

OPERATOR = "operator-key-0123456789"
AUTH = {"Authorization": f"Bearer {OPERATOR}"}
LIMIT = 1 << 20
AXLE_VEHICLE = b"""[vehicle]
model = "axle"
mass_kg = 840.0
spring_stiffness_N_per_m = 26000
tyre_stiffness_N_per_m = 210000
tyre_viscoelastic_coefficient = 0.97
track_m = 1.5
"""


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    settings = ServiceSettings(
        data_dir=tmp_path_factory.mktemp("uploads"),
        keys=KeyRing({OPERATOR: Role.OPERATOR}),
        max_upload_bytes=LIMIT,
    )
    app = create_app(settings)

    add_broken_route(app)
    with LiveServer(app) as server, httpx.Client(base_url=server.url, headers=AUTH) as c:
        yield c


def jobs_total(client: httpx.Client) -> int:
    return client.get("/api/v1/jobs").json()["total"]


@pytest.mark.parametrize(
    ("recording", "vehicle", "options", "field", "message"),
    [
        (b"t,a,b\n0,1,2\n0.001,1,2\n0.002,1,2\n", None, {}, "recording", "columns t,a,b are neither"),
        (b"t,x_s,x_t,x_r\n0,0,0,0\n0.001,0,x,0\n", None, {}, "recording", "recording.csv:3: not a number"),
        (b"t,x_s,x_t,x_r\n0,0,0,0\n0.001,0,0,0\n0.003,0,0,0\n", None, {}, "recording", "not uniform"),
        (b"\xff\xfe\x00\x81binary", None, {}, "recording", "not a text file"),
        (b"t,x_s,x_t,x_r\n0,0,\x00,0\n", None, {}, "recording", ""),
        (None, b"[vehicle]\nmass_kg = 1\n", {}, "vehicle", "missing required key 'model'"),
        (None, b"[vehicle\n", {}, "vehicle", "not valid TOML"),
        (None, AXLE_VEHICLE, {}, "recording", "quarter-car channels but the vehicle file is for a axle"),
        (None, None, {"points": "99"}, "points", "points: Input should be less than or equal to 60"),
        (None, None, {"solver": "magic"}, "solver", "solver: Input should be 'exact' or 'de'"),
        (None, None, {"generations": "0"}, "generations", "greater than or equal to 1"),
        (None, None, {"model": "axle"}, "model", "model is axle but the vehicle file says quarter-car"),
        (None, None, {"tyres": "spring"}, "tyres", "unknown field 'tyres'"),
    ],
)
def test_bad_input_is_refused_at_submit_naming_the_field(
    client: httpx.Client,
    inputs: SimulatedInputs,
    recording: bytes | None,
    vehicle: bytes | None,
    options: dict[str, str],
    field: str,
    message: str,
) -> None:
    before = jobs_total(client)
    files = {
        "recording": ("recording.csv", recording if recording is not None else inputs.recording.read_bytes()),
        "vehicle": ("vehicle.toml", vehicle if vehicle is not None else inputs.vehicle.read_bytes()),
    }
    response = client.post("/api/v1/jobs", files=files, data=options)
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert error["code"] == "invalid" and error["field"] == field
    assert message in error["message"]
    assert "\n" not in error["message"] and "Traceback" not in response.text
    assert jobs_total(client) == before  # nothing was queued


def test_missing_files_are_named(client: httpx.Client, inputs: SimulatedInputs) -> None:
    response = client.post("/api/v1/jobs", files={"recording": ("r.csv", inputs.recording.read_bytes())})
    assert response.status_code == 422
    assert response.json()["error"] == {
        "code": "invalid",
        "message": "vehicle: Field required",
        "field": "vehicle",
    }


def test_an_upload_over_the_limit_is_refused_with_413(client: httpx.Client, inputs: SimulatedInputs) -> None:
    big = b"t,x_s,x_t,x_r\n" + b"0.000000,0,0,0\n" * (LIMIT // 15 + 1)
    files = {"recording": ("big.csv", big), "vehicle": ("vehicle.toml", inputs.vehicle.read_bytes())}
    response = client.post("/api/v1/jobs", files=files)
    assert response.status_code == 413
    error = response.json()["error"]
    assert error["code"] == "payload_too_large"
    assert error["message"] == f"request body larger than the upload limit of 1 MiB ({LIMIT} bytes)"


def test_a_chunked_upload_is_cut_off_at_the_limit(client: httpx.Client) -> None:
    sent = 0

    def body() -> Iterator[bytes]:  # no Content-Length: the server counts what arrives
        nonlocal sent
        yield b'--abc\r\nContent-Disposition: form-data; name="recording"; filename="r.csv"\r\n\r\n'
        chunk = b"0.001,0,0,0\n" * 5000
        while sent < 4 * LIMIT:
            sent += len(chunk)
            yield chunk

    response = client.post(
        "/api/v1/jobs", content=body(), headers={"Content-Type": "multipart/form-data; boundary=abc"}
    )
    assert response.status_code == 413
    assert response.json()["error"]["code"] == "payload_too_large"


def test_non_multipart_bodies_are_typed_errors(client: httpx.Client) -> None:
    for response in (
        client.post("/api/v1/jobs", json={"recording": "x"}),
        client.post(
            "/api/v1/jobs", content=b"--abc\r\nbroken", headers={"Content-Type": "multipart/form-data"}
        ),
    ):
        assert response.status_code in (400, 422), response.text
        assert set(response.json()["error"]) >= {"code", "message"}


def test_unknown_routes_and_methods_are_typed_errors(client: httpx.Client) -> None:
    missing = client.get("/api/v1/nothing-here")
    assert missing.status_code == 404 and missing.json()["error"]["code"] == "not_found"
    wrong = client.put("/api/v1/status")
    assert wrong.status_code == 405 and wrong.json()["error"]["code"] == "method_not_allowed"
    bad_id = client.get("/api/v1/jobs/abc")
    assert bad_id.status_code == 422 and bad_id.json()["error"]["field"] == "job_id"


def test_an_unexpected_error_is_a_typed_500_without_details(client: httpx.Client) -> None:
    response = client.get("/api/v1/broken")
    assert response.status_code == 500
    error_id = response.headers["X-Error-Id"]
    assert response.json() == {
        "error": {
            "code": "internal",
            "message": f"internal error (error id {error_id}); the service log has the details under that id",
        }
    }
    assert "secret" not in response.text and "Traceback" not in response.text
