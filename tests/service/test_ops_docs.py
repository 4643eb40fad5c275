"""The API docs served from the package (issue 31, item 3): /docs names only the service's own URLs, its
assets (Swagger UI 5, from the installed fastapi-offline package) are served, its policy allows nothing
else, and a headless Chromium renders the operations with every request it made going to the service."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from headless_chromium import chromium_driver, console_errors, find_chromium
from live_server import LiveServer, wait_until

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.docs_page import ASSETS, ASSETS_PATH, assets_dir

VIEWER = "viewer-key-0123456789"
MEDIA_TYPES = {"script": "javascript", "style": "text/css", "icon": "image/png"}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("docs"), keys=KeyRing({VIEWER: Role.VIEWER}))
    with LiveServer(create_app(settings)) as live:
        yield live


def test_the_docs_page_references_only_the_services_own_urls(server: LiveServer) -> None:
    page = httpx.get(f"{server.url}/docs")
    assert page.status_code == 200
    assert "http://" not in page.text and "https://" not in page.text and "//cdn" not in page.text
    references = re.findall(r'\b(?:src|href)="([^"]*)"', page.text)
    assert sorted(references) == sorted(f"{ASSETS_PATH}/{name}" for name in ASSETS.values())
    inline = re.findall(r"<script>(.*?)</script>", page.text, flags=re.DOTALL)
    assert len(inline) == 1 and "url: '/api/v1/openapi.json'" in inline[0]
    assert '"validatorUrl": null' in inline[0]  # Swagger UI's online validator: off
    directives = dict(d.split(" ", 1) for d in page.headers["content-security-policy"].split("; "))
    assert directives["script-src"].startswith("'self' 'sha256-")
    assert directives["style-src"] == "'self' 'unsafe-inline'" and directives["connect-src"] == "'self'"
    assert "http" not in page.headers["content-security-policy"]


@pytest.mark.parametrize("asset", sorted(ASSETS))
def test_the_docs_assets_are_served_without_a_key(server: LiveServer, asset: str) -> None:
    name = ASSETS[asset]
    answer = httpx.get(f"{server.url}{ASSETS_PATH}/{name}")
    assert answer.status_code == 200
    assert MEDIA_TYPES[asset] in answer.headers["content-type"]
    assert answer.content == (assets_dir() / name).read_bytes()


def test_the_bundle_is_swagger_ui_5_which_reads_the_openapi_3_1_schema(server: LiveServer) -> None:
    schema = httpx.get(f"{server.url}/api/v1/openapi.json").json()
    assert schema["openapi"].startswith("3.1")
    bundle = (assets_dir() / ASSETS["script"]).read_text(encoding="utf-8")
    assert re.search(r'"5\.\d+\.\d+"', bundle), "not Swagger UI 5: OpenAPI 3.1 would not render"


def test_a_browser_renders_the_docs_with_every_request_to_the_service(
    server: LiveServer, tmp_path: Path
) -> None:
    with chromium_driver(find_chromium(), tmp_path) as driver:
        driver.get(f"{server.url}/docs")  # type: ignore[attr-defined]
        operations = wait_until(
            lambda: driver.find_elements("css selector", ".opblock"),  # type: ignore[attr-defined]
            60,
            "Swagger UI listing the operations",
        )
        resources = driver.execute_script(  # type: ignore[attr-defined]
            "return performance.getEntriesByType('resource').map(e => e.name)"
        )
        errors = console_errors(driver)
    assert len(operations) >= 20  # every operation of /api/v1
    assert f"{server.url}/api/v1/openapi.json" in resources
    outside = [url for url in resources if not url.startswith(server.url + "/")]
    assert outside == [], f"requests that left the service: {outside}"
    assert errors == []  # a request the policy blocked would be a console error
