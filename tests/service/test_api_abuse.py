"""The service under abuse (issue 14), each case over HTTP against the real uvicorn server with the
in-process simulated bench: undersampled recordings refused on every path, physical bounds at submit,
options the schema allows that used to fail, inputs that used to give a 500, a 500 that leaves the client
able to go on, no server paths in exports, request bodies that stop arriving, event streams per key,
OPTIONS and Allow, long input cut in messages, strict flags, keyed key ids."""

from __future__ import annotations

import hashlib
import hmac
import logging
import socket
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import h5py
import httpx
import pytest
from live_server import LiveServer, SimulatedInputs, add_broken_route, wait_until
from live_server import wait_for_status as wait_for

from daq.bench_config import write_bench_config
from daq.formats.vehicle_file import format_vehicle
from drivers.exciter.codes import CommandCode
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.app import FINGERPRINT_SECRET_FILE
from service.cli.main import main as cli_main
from service.simulated_bench import SimulatedBench, vehicle_preset
from simulators.vehicle_sim import default_quarter_car

OPERATOR = "operator-key-0123456789"
VIEWER = "viewer-key-0123456789abc"
ADMIN = "admin-key-0123456789abcd"
AUTH = {"Authorization": f"Bearer {OPERATOR}"}
BODY_TIMEOUT_S = 1.0
MAX_STREAMS = 2
VEHICLE_TOML = format_vehicle(default_quarter_car().known)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    settings = ServiceSettings(
        data_dir=tmp_path_factory.mktemp("abuse"),
        keys=KeyRing({OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER, ADMIN: Role.ADMIN}),
        simulated=True,
        body_timeout_s=BODY_TIMEOUT_S,
        max_streams_per_key=MAX_STREAMS,
    )
    app = create_app(settings)

    add_broken_route(app)
    with LiveServer(app) as live:
        yield live


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, headers=AUTH, timeout=120) as c:
        yield c


def data_dir(server: LiveServer) -> Path:
    return Path(server.app.state.services.settings.data_dir)


def submit(
    client: httpx.Client,
    recording: bytes,
    vehicle: bytes,
    options: dict[str, str] | None = None,
    path: str = "/api/v1/jobs",
) -> httpx.Response:
    files = {"recording": ("recording.csv", recording), "vehicle": ("vehicle.toml", vehicle)}
    return client.post(path, files=files, data=options or {})


def assert_refused(response: httpx.Response, field: str, *fragments: str) -> dict[str, Any]:
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert error["field"] == field, error
    for fragment in fragments:
        assert fragment in error["message"], error
    return error


def decimated(csv_text: str, step: int, metadata: tuple[str, ...] = ()) -> bytes:
    """The recording CSV with every `step`-th row (its grid `step` times coarser), metadata lines added."""
    lines = csv_text.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    rows = lines[header + 1 :][::step]
    return "\n".join([*metadata, lines[header], *rows, ""]).encode()


def vehicle_with(**values: str) -> bytes:
    lines = []
    for line in VEHICLE_TOML.splitlines():
        key = line.split("=")[0].strip()
        lines.append(f"{key} = {values[key]}" if key in values else line)
    return "\n".join(lines).encode()


# ---- undersampled recordings ---------------------------------------------------------------------------


@pytest.mark.parametrize("path", ["/api/v1/jobs", "/api/v1/diagnoses"])
def test_a_recording_on_a_20_Hz_grid_is_refused_at_submit(
    client: httpx.Client, inputs: SimulatedInputs, path: str
) -> None:
    """No rate metadata: the grid itself is judged against the bench's 0-20 Hz sweep (>= 100 Hz needed)."""
    recording = decimated(inputs.recording.read_text(), 50)  # 1 kHz -> 20 Hz
    error = assert_refused(
        submit(client, recording, inputs.vehicle.read_bytes(), path=path),
        "recording",
        "sample grid is 20.0 Hz",
    )
    assert "at least 100 Hz" in error["message"]
    # 200 Hz (10 samples per period at 20 Hz) passes the check: the job is taken
    ok = submit(
        client,
        decimated(inputs.recording.read_text(), 5),
        inputs.vehicle.read_bytes(),
        {"output_error": "false"},
    )
    assert ok.status_code == 201, ok.text
    client.post(f"/api/v1/jobs/{ok.json()['id']}/cancel")


def test_a_recording_whose_metadata_says_60_Hz_is_refused_at_submit(
    client: httpx.Client, inputs: SimulatedInputs
) -> None:
    recording = decimated(inputs.recording.read_text(), 1, ("# rate_Hz.x_t: 60", "# sweep_stop_Hz: 20"))
    assert_refused(
        submit(client, recording, inputs.vehicle.read_bytes()),
        "recording",
        "channel x_t was sampled at 60.0 Hz",
    )


def test_the_cli_refuses_the_undersampled_recording_too(
    inputs: SimulatedInputs, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "decimated.csv"
    path.write_bytes(decimated(inputs.recording.read_text(), 50))
    code = cli_main(["identify", str(path), "--vehicle", str(inputs.vehicle)])
    err = capsys.readouterr().err
    assert code != 0 and "sample grid is 20.0 Hz" in err and len(err.strip().splitlines()) == 1, err


def test_a_sweep_job_on_a_recording_its_lasers_could_not_carry_is_refused(
    client: httpx.Client, server: LiveServer
) -> None:
    """The sweep job path: the recording's rate metadata (a polled amplifier that achieved 60 Hz) against
    the sweep's top frequency from the recording's own sweep settings."""
    response = client.post(
        "/api/v1/sweeps", json={"duration_s": 2, "settle_s": 0.5, "vehicle_toml": VEHICLE_TOML}
    )
    assert response.status_code == 201, response.text
    sweep = wait_for(client, response.json()["links"]["self"], "complete", "failed", "aborted")
    assert sweep["status"] == "complete", sweep
    h5 = data_dir(server) / "sweeps" / sweep["recording_file"]
    with h5py.File(h5, "r+") as f:
        assert float(f.attrs["sweep_stop_Hz"]) == 20.0
        f.attrs["rate_Hz.x_s"] = 60.0  # as a polled amplifier on a slow line would have reported
    assert_refused(
        client.post(f"/api/v1/sweeps/{sweep['id']}/jobs", json={}),
        "recording",
        "channel x_s was sampled at 60.0 Hz",
        "20 Hz top",
    )


# ---- physical bounds ---------------------------------------------------------------------------------


@pytest.mark.parametrize("mass", ["9.2e18", "inf", "1e308", "1e-300", "nan"])
def test_an_absurd_mass_is_refused_at_submit_naming_the_key(
    client: httpx.Client, inputs: SimulatedInputs, mass: str
) -> None:
    response = submit(client, inputs.recording.read_bytes(), vehicle_with(mass_kg=mass))
    error = assert_refused(response, "vehicle", "mass_kg")
    assert "1 to 20000 kg" in error["message"] or "must be > 0" in error["message"], error


def test_absurd_stiffness_and_sweep_vehicle_are_refused(
    client: httpx.Client, inputs: SimulatedInputs
) -> None:
    assert_refused(
        submit(client, inputs.recording.read_bytes(), vehicle_with(tyre_stiffness_N_per_m="1e-9")),
        "vehicle",
        "tyre_stiffness_N_per_m = 1e-09",
        "100 to 1e+08 N/m",
    )
    body = {"duration_s": 2, "vehicle_toml": vehicle_with(mass_kg="9.2e18").decode()}
    assert_refused(client.post("/api/v1/sweeps", json=body), "vehicle_toml", "mass_kg = 9.2e+18")
    schedule = {**body, "job": {}}
    admin = {"Authorization": f"Bearer {ADMIN}"}
    assert_refused(client.post("/api/v1/schedules", json=schedule, headers=admin), "vehicle_toml", "mass_kg")


def test_one_huge_value_in_the_recording_is_refused_naming_channel_and_time(
    client: httpx.Client, inputs: SimulatedInputs
) -> None:
    lines = inputs.recording.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    t, _x_s, x_t, x_r = lines[header + 1001].split(",")
    lines[header + 1001] = ",".join([t, "1e308", x_t, x_r])
    assert_refused(
        submit(client, "\n".join(lines).encode(), inputs.vehicle.read_bytes()),
        "recording",
        "channel x_s reads 1e+308 m at t = 1 s",
        "±1 m",
    )


@pytest.mark.parametrize("duration", [1e-9, 0.5, 1e6])
def test_a_sweep_duration_out_of_bounds_is_refused(client: httpx.Client, duration: float) -> None:
    response = client.post("/api/v1/sweeps", json={"duration_s": duration, "vehicle_toml": VEHICLE_TOML})
    assert_refused(response, "duration_s")


# ---- options the schema allows -------------------------------------------------------------------------


@pytest.mark.parametrize("points", ["3", "4"])
def test_fewer_points_than_the_tanh_fit_needs_are_refused(
    client: httpx.Client, inputs: SimulatedInputs, points: str
) -> None:
    response = submit(client, inputs.recording.read_bytes(), inputs.vehicle.read_bytes(), {"points": points})
    assert_refused(response, "points", "greater than or equal to 5")


def test_five_points_succeed(client: httpx.Client, inputs: SimulatedInputs) -> None:
    options = {"points": "5", "output_error": "false"}
    response = submit(client, inputs.recording.read_bytes(), inputs.vehicle.read_bytes(), options)
    assert response.status_code == 201, response.text
    job = wait_for(client, response.json()["links"]["self"], "succeeded", "failed", timeout_s=300)
    assert job["status"] == "succeeded", job
    assert len(job["result"]["curves"][0]["force_N"]) == 5


# ---- inputs that used to give a 500; a 500 that remains ---------------------------------------------


def test_a_vehicle_file_nested_100000_deep_is_a_422_and_the_connection_goes_on(
    client: httpx.Client, inputs: SimulatedInputs
) -> None:
    deep = b"a = " + b"[" * 100_000
    assert_refused(submit(client, inputs.recording.read_bytes(), deep), "vehicle", "nested too deeply")
    body = {"duration_s": 2, "vehicle_toml": deep.decode()}
    assert_refused(client.post("/api/v1/sweeps", json=body), "vehicle_toml", "nested too deeply")
    assert client.get("/api/v1/status").status_code == 200  # same keep-alive client


def test_a_500_closes_the_connection_cleanly_and_names_an_error_id_in_the_log(
    client: httpx.Client, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.ERROR, logger="shockbench.api"):
        response = client.get("/api/v1/broken")
    assert response.status_code == 500
    assert response.headers["connection"] == "close"
    error_id = response.headers["x-error-id"]
    assert error_id in response.json()["error"]["message"] and "secret" not in response.text
    logged = [r for r in caplog.records if error_id in r.getMessage()]
    assert logged and logged[0].exc_info is not None  # the traceback is in the log, under the id
    for _ in range(3):  # the client goes on: a fresh connection, no failed request
        assert client.get("/api/v1/status").status_code == 200


# ---- no server paths -------------------------------------------------------------------------------------


def test_the_recording_csv_and_job_reasons_carry_no_server_paths(
    client: httpx.Client, server: LiveServer
) -> None:
    response = client.post(
        "/api/v1/sweeps", json={"duration_s": 2, "settle_s": 0.5, "vehicle_toml": VEHICLE_TOML}
    )
    sweep = wait_for(client, response.json()["links"]["self"], "complete", "failed", "aborted")
    csv = client.get(sweep["links"]["recording_csv"])
    assert csv.status_code == 200
    metadata = dict(line[2:].split(": ", 1) for line in csv.text.splitlines() if line.startswith("# "))
    assert metadata["source"] == sweep["recording_file"]
    assert metadata["vehicle_file"] == f"{sweep['id']}.vehicle.toml"
    assert str(data_dir(server)) not in csv.text
    job = client.post(f"/api/v1/sweeps/{sweep['id']}/jobs", json={"output_error": False})
    assert job.status_code == 201, job.text
    done = wait_for(client, job.json()["links"]["self"], "succeeded", "failed", timeout_s=300)
    assert str(data_dir(server)) not in str(done)


# ---- bodies that stop arriving, streams per key, methods -------------------------------------------------


def test_a_body_shorter_than_its_content_length_is_answered_408_and_the_connection_freed(
    server: LiveServer,
) -> None:
    host, port = server.url.removeprefix("http://").split(":")
    began = time.monotonic()  # before the connection: the server's timer may start when it accepts
    with socket.create_connection((host, int(port)), timeout=30) as raw:
        raw.sendall(
            b"POST /api/v1/jobs HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer "
            + OPERATOR.encode()
            + b"\r\nContent-Type: multipart/form-data; boundary=XX\r\nContent-Length: 100000\r\n\r\n--XX\r\n"
        )
        answer = b""
        while chunk := raw.recv(65536):  # the server answers, then closes: recv returns b""
            answer += chunk
        waited = time.monotonic() - began
    head = answer.split(b"\r\n\r\n")[0].decode().lower()
    assert head.startswith("http/1.1 408"), answer
    assert "connection: close" in head
    assert b"request_timeout" in answer
    assert BODY_TIMEOUT_S <= waited < BODY_TIMEOUT_S + 20


def test_event_streams_per_key_are_limited(
    client: httpx.Client, server: LiveServer, inputs: SimulatedInputs
) -> None:
    job = submit(
        client,
        inputs.recording.read_bytes(),
        inputs.vehicle.read_bytes(),
        {"solver": "de", "generations": "200000"},
    ).json()  # runs until cancelled
    events = f"/api/v1/jobs/{job['id']}/events"
    viewer = {"Authorization": f"Bearer {VIEWER}"}
    try:
        with ExitStack() as streams:
            for _ in range(MAX_STREAMS):
                opened = streams.enter_context(client.stream("GET", events))
                assert opened.status_code == 200
            refused = client.get(events)
            assert refused.status_code == 429, refused.text
            assert refused.json()["error"]["code"] == "too_many_requests"
            assert int(refused.headers["retry-after"]) > 0
            with client.stream("GET", events, headers=viewer) as other_key:  # another key is not limited
                assert other_key.status_code == 200

        # closed: the places are free again (the server notices the closed connections)
        def reopened() -> bool:
            with client.stream("GET", events) as again:
                return again.status_code == 200

        assert wait_until(reopened, 30, "a stream after the others closed")
    finally:
        client.post(f"/api/v1/jobs/{job['id']}/cancel")
        wait_for(client, f"/api/v1/jobs/{job['id']}", "cancelled", "failed", "succeeded")


def test_options_and_405_name_every_method_of_the_path(client: httpx.Client) -> None:
    options = client.options("/api/v1/jobs")
    assert options.status_code == 204
    assert options.headers["allow"] == "GET, OPTIONS, POST"
    assert client.options("/api/v1/jobs/1").headers["allow"] == "GET, OPTIONS"
    wrong = client.delete("/api/v1/jobs")
    assert wrong.status_code == 405 and wrong.headers["allow"] == "GET, OPTIONS, POST"
    assert client.options("/api/v1/no-such-thing").status_code == 404


# ---- long input, strict flags, key ids -----------------------------------------------------------------


def test_a_header_of_a_million_columns_is_cut_in_the_message(
    client: httpx.Client, inputs: SimulatedInputs
) -> None:
    header = "t," + ",".join(f"c{i}" for i in range(1_000_000))
    response = submit(client, f"{header}\n".encode(), inputs.vehicle.read_bytes())
    error = assert_refused(response, "recording", "columns t,c0,c1")
    assert len(error["message"]) <= 300 and "more characters" in error["message"]
    assert len(response.content) < 1000


@pytest.mark.parametrize("value", ["0", "1", "yes", "off"])
def test_a_flag_takes_only_true_or_false(client: httpx.Client, inputs: SimulatedInputs, value: str) -> None:
    response = submit(
        client, inputs.recording.read_bytes(), inputs.vehicle.read_bytes(), {"output_error": value}
    )
    assert_refused(response, "output_error", "true or false")


def test_viewers_see_keyed_key_ids_not_hashes_of_the_key(
    client: httpx.Client, server: LiveServer, inputs: SimulatedInputs
) -> None:
    job = submit(
        client, inputs.recording.read_bytes(), inputs.vehicle.read_bytes(), {"output_error": "false"}
    )
    assert job.status_code == 201, job.text
    seen = httpx.get(
        f"{server.url}/api/v1/jobs/{job.json()['id']}", headers={"Authorization": f"Bearer {VIEWER}"}
    ).json()["submitted_by"]
    assert seen != hashlib.sha256(OPERATOR.encode()).hexdigest()[:12]
    secret = (data_dir(server) / FINGERPRINT_SECRET_FILE).read_bytes()
    assert seen == hmac.new(secret, OPERATOR.encode(), hashlib.sha256).hexdigest()[:12]
    assert (data_dir(server) / FINGERPRINT_SECRET_FILE).stat().st_mode & 0o077 == 0


def test_sweeps_and_schedules_the_bench_cannot_record_fast_enough_are_refused(tmp_path: Path) -> None:
    """Sweep and schedule paths: the top frequency is the sweep's own, the rate the bench's slowest
    streaming amplifier (here 20 Hz): refused at submit, before anything moves."""
    slow = SimulatedBench(vehicle_preset("quarter-car"), realtime=True, laser_sample_period_s=0.05)
    config = write_bench_config(slow.start(), tmp_path / "bench.toml")
    try:
        settings = ServiceSettings(
            data_dir=tmp_path / "data",
            keys=KeyRing({OPERATOR: Role.OPERATOR, ADMIN: Role.ADMIN}),
            bench_config=config,
        )
        with LiveServer(create_app(settings)) as live, httpx.Client(base_url=live.url, timeout=60) as c:
            body = {"duration_s": 2, "stop_Hz": 20, "vehicle_toml": VEHICLE_TOML}
            sweep = c.post("/api/v1/sweeps", json=body, headers=AUTH)
            assert_refused(sweep, "stop_Hz", "the bench records at 20 Hz", "at most 4 Hz")
            admin = {"Authorization": f"Bearer {ADMIN}"}
            test = c.post("/api/v1/schedules", json={**body, "job": {}}, headers=admin)
            assert_refused(test, "stop_Hz", "the bench records at 20 Hz")
            # a sweep it can carry (up to 4 Hz) is taken
            assert c.post("/api/v1/sweeps", json={**body, "stop_Hz": 4}, headers=AUTH).status_code == 201
            assert slow.exciter.commands[0] is CommandCode.STOP  # the start-up stop came first
    finally:
        slow.close()


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--max-streams-per-key", "0"], "--max-streams-per-key must be at least 1"),
        (["--body-timeout-s", "0"], "--body-timeout-s must lie in (0, 3600]"),
    ],
)
def test_serve_refuses_limits_that_make_no_sense(
    option: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from service.cli.serve import main as serve_main

    assert serve_main(["--data", str(tmp_path), *option]) == 2
    assert capsys.readouterr().err.strip() == f"shockbench serve: error: {message}"
