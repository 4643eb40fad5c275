"""The API docs at `/docs`: FastAPI's Swagger UI page, served with everything it loads from the service
itself, so that it works on a lane without internet like the operator page does.

Swagger UI's script, stylesheet and icon come from the installed `fastapi-offline` package (its `static/`
folder: Swagger UI 5, which reads the OpenAPI 3.1 schema FastAPI writes; `swagger-ui-bundle` ships Swagger
UI 4, which cannot), served under `/docs/assets/` (`ASSETS_PATH`). Nothing is copied into this repository.
The page gets its own Content-Security-Policy (`docs_policy`): scripts and styles from the service only
plus the page's one inline script by its hash, inline styles (Swagger UI sets style attributes), and
requests to the service only (the schema, "Try it out"); the online validator is switched off.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

from service.api.security_headers import script_hashes

DOCS_PATH = "/docs"
ASSETS_PATH = "/docs/assets"
ASSETS = {"script": "swagger-ui-bundle.js", "style": "swagger-ui.css", "icon": "favicon.png"}
"""The files of the assets folder the page loads."""


def assets_dir() -> Path:
    """fastapi-offline's folder of Swagger UI (and ReDoc) files, where the package is installed."""
    return Path(str(files("fastapi_offline").joinpath("static")))


def docs_policy(html: str) -> str:
    """The docs page's policy: its scripts and styles from the service (and its inline script by hash),
    inline styles, images from the service and data: URLs, requests to the service only."""
    return "; ".join(
        [
            "default-src 'none'",
            f"script-src 'self' {' '.join(script_hashes(html))}",
            "style-src 'self' 'unsafe-inline'",
            "img-src 'self' data:",
            "connect-src 'self'",
            "base-uri 'none'",
            "form-action 'none'",
            "frame-ancestors 'none'",
        ]
    )


def docs_html(openapi_url: str, title: str) -> str:
    """Swagger UI's page for the schema at `openapi_url`, loading only the service's assets."""
    page = get_swagger_ui_html(
        openapi_url=openapi_url,
        title=title,
        swagger_js_url=f"{ASSETS_PATH}/{ASSETS['script']}",
        swagger_css_url=f"{ASSETS_PATH}/{ASSETS['style']}",
        swagger_favicon_url=f"{ASSETS_PATH}/{ASSETS['icon']}",
        swagger_ui_parameters={"validatorUrl": None},
    )
    return bytes(page.body).decode()


def install_docs(app: FastAPI) -> None:
    """GET /docs (the page, with `docs_policy`) and its assets under /docs/assets. (The app is made with
    docs_url=None: FastAPI's own route would load Swagger UI from a CDN.)"""
    assert app.openapi_url is not None
    html = docs_html(app.openapi_url, f"{app.title} - Swagger UI")
    headers = {"Content-Security-Policy": docs_policy(html)}
    app.mount(ASSETS_PATH, StaticFiles(directory=assets_dir()), name="docs-assets")

    @app.get(DOCS_PATH, include_in_schema=False)
    async def docs() -> HTMLResponse:
        return HTMLResponse(html, headers=headers)
