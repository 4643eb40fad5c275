"""Schemathesis against the service's own OpenAPI schema, on the real server with the simulated bench:
generated requests to every operation (with an admin key, so they get past access control) never produce
a 5xx, and every answer is documented and matches its schema: status code, content type, headers
(Location on a 201) and body.

Random bytes are never a recording and random text never a vehicle file, so generated requests alone
would only ever be refused (422) or miss (404). Hooks seed them with valid inputs: the upload bodies
often carry a real recording CSV and its vehicle file, sweep and scheduled-test bodies a vehicle file and
settings the bench's envelope accepts, and ids often name the jobs, sweeps and tests made so far. The last
test reports how many jobs, sweeps and scheduled tests the generated requests created, and requires some
of each."""

from __future__ import annotations

import json
import tempfile
from collections import Counter
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import Any

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from live_server import LiveServer, simulated_inputs
from schemathesis import GenerationMode
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from daq.formats.recording_csv import read_recording_csv
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app

ADMIN = "admin-key-0123456789abc"
AUTH = {"Authorization": f"Bearer {ADMIN}"}
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
]
MAX_EXAMPLES = 20
"""Per operation and mode; with the coverage phase about 1500 requests in all, about a minute."""
UPLOAD_PATHS = {"/api/v1/jobs", "/api/v1/diagnoses"}
VALIDATIONS = "/api/v1/validations"
"""Takes the recording and an identified model (JSON) instead of a vehicle file."""
ID_PARAMETERS = ("job_id", "sweep_id", "test_id")
VALID_SWEEPS = [
    {"start_Hz": 0.5, "stop_Hz": 20.0, "amplitude_m": 0.004, "duration_s": 1.0, "settle_s": 0.2},
    {"start_Hz": 2.0, "stop_Hz": 15.0, "amplitude_m": 0.002, "duration_s": 2.0, "law": "logarithmic"},
]
"""Settings the simulated bench's envelope accepts: short, so that the bench is soon free again."""

created: Counter[str] = Counter()
"""Path -> 201 answers to the generated requests (reported by the last test)."""
statuses: Counter[int] = Counter()
"""Status code -> answers to the generated requests."""


@cache
def valid_inputs() -> tuple[bytes, str]:
    """A real recording CSV and its vehicle file (the simulator's; cached with the session's `inputs`)."""
    with tempfile.TemporaryDirectory() as folder:
        files = simulated_inputs(Path(folder), seconds=6.0, seed=1)
        return files.recording.read_bytes(), files.vehicle.read_text()


@cache
def valid_model() -> bytes:
    """The model identify --json gives for the valid recording (for the validations' uploads)."""
    from daq.formats.vehicle_file import parse_vehicle
    from estimator.identify import identify

    recording, vehicle = valid_inputs()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "rec.csv"
        path.write_bytes(recording)
        result = identify(read_recording_csv(path), parse_vehicle(vehicle))
    return json.dumps(result.to_json()).encode()


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    settings = ServiceSettings(
        data_dir=tmp_path_factory.mktemp("schema"),
        keys=KeyRing({ADMIN: Role.ADMIN}),
        max_upload_bytes=1 << 20,
        simulated=True,  # the bench endpoints answer (without a bench they answer 503)
    )
    with LiveServer(create_app(settings)) as server:
        yield server


def openapi_document() -> dict:
    """The schema as the app publishes it at /api/v1/openapi.json (made without starting the app)."""
    return create_app(ServiceSettings(data_dir=Path("unused"), keys=KeyRing({ADMIN: Role.ADMIN}))).openapi()


LIVE_STREAM = "bench_live"
"""GET /bench/live streams until the client leaves, and schemathesis reads a body to its end: it is left
out here (tests/service/test_api_operator.py reads it, test_api_contract.py checks its documented events)."""
schema = schemathesis.openapi.from_dict(openapi_document()).exclude(operation_id=LIVE_STREAM)
schema.config.generation.update(modes=[GenerationMode.POSITIVE, GenerationMode.NEGATIVE])


@schema.hook
def flatmap_body(context: schemathesis.HookContext, body: Any) -> st.SearchStrategy:
    """Often a valid recording and vehicle file (uploads), or a valid vehicle file and sweep settings
    (sweeps, scheduled tests), with the generated options; else the body as generated."""
    operation = context.operation
    if not isinstance(body, dict) or operation is None or operation.method.upper() != "POST":
        return st.just(body)
    recording, vehicle = valid_inputs()
    if operation.path in UPLOAD_PATHS:
        seeded = {**body, "recording": recording, "vehicle": vehicle.encode()}
        return st.sampled_from([seeded, body])
    if operation.path == VALIDATIONS:
        return st.sampled_from([{**body, "recording": recording, "model": valid_model()}, body])
    if "vehicle_toml" in body or operation.path in ("/api/v1/sweeps", "/api/v1/schedules"):
        options = {"job": {}} if operation.path == "/api/v1/schedules" else {}
        seeded = [{**body, **options, **sweep, "vehicle_toml": vehicle} for sweep in VALID_SWEEPS]
        return st.sampled_from([*seeded, {**body, "vehicle_toml": vehicle}, body])
    return st.just(body)


@schema.hook
def flatmap_path_parameters(
    context: schemathesis.HookContext, parameters: dict[str, Any] | None
) -> st.SearchStrategy:
    """Ids: often one of the first few (made by earlier requests), else as generated."""
    if not parameters or not any(name in parameters for name in ID_PARAMETERS):
        return st.just(parameters)
    small = st.integers(min_value=1, max_value=4)
    return st.one_of(
        st.fixed_dictionaries(
            {k: small if k in ID_PARAMETERS else st.just(v) for k, v in parameters.items()}
        ),
        st.just(parameters),
    )


@schema.parametrize()
@settings(max_examples=MAX_EXAMPLES, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
def test_no_request_gets_a_server_error(case: schemathesis.Case, live: LiveServer) -> None:
    response = case.call_and_validate(base_url=live.url, headers=AUTH, checks=CHECKS, timeout=30)
    statuses[response.status_code] += 1
    if response.status_code == 201:
        created[case.operation.path] += 1


def test_the_generated_requests_created_jobs_sweeps_and_tests(live: LiveServer) -> None:
    """Runs after the generated requests (same module, same server): what they made."""
    with httpx.Client(base_url=live.url, headers=AUTH, timeout=30) as client:
        totals = {
            name: client.get(f"/api/v1/{name}", params={"limit": 1}).json()["total"]
            for name in ("jobs", "sweeps", "schedules")
        }
    print(f"\nschemathesis: {statuses.total()} requests, by status {dict(sorted(statuses.items()))}")
    print(f"created (201) by path {dict(created)}; in the store {totals}")
    assert created["/api/v1/jobs"] > 0 and created["/api/v1/diagnoses"] > 0 and created[VALIDATIONS] > 0
    assert created["/api/v1/sweeps"] > 0 and created["/api/v1/schedules"] > 0
    assert totals["jobs"] >= created["/api/v1/jobs"] + created["/api/v1/diagnoses"] + created[VALIDATIONS]
