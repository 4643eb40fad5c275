"""Schemathesis against the service's own OpenAPI schema, on the real server: generated requests to every
operation (with an admin key, so they get past access control) never produce a 500, and every answer is
documented and matches its schema."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis import GenerationMode
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.testing import LiveServer

ADMIN = "admin-key-0123456789abc"
AUTH = {"Authorization": f"Bearer {ADMIN}"}
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance]


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


schema = schemathesis.openapi.from_dict(openapi_document())
schema.config.generation.update(modes=[GenerationMode.POSITIVE, GenerationMode.NEGATIVE])


@schema.parametrize()
@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
def test_no_request_gets_a_server_error(case: schemathesis.Case, live: LiveServer) -> None:
    case.call_and_validate(base_url=live.url, headers=AUTH, checks=CHECKS, timeout=30)
