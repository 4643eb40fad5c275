"""The operator page, served by the service itself: `GET /` is service/web/index.html, `/web/...` the rest
of service/web/ (scripts, styles, vendored libraries). No build step, no CDN: a workshop without internet
gets everything from the service. The page talks to the API with the key the operator types (a Bearer
header); the files themselves hold no secret and need no key."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

WEB_DIR = Path(__file__).resolve().parent.parent / "web"
"""service/web/: the page's files."""
NO_STORE = {"Cache-Control": "no-cache"}
"""The page is revalidated on each load, so that an updated service is never shown with an old script."""


def install_page(app: FastAPI) -> None:
    """Serve the page at `/` and its files under `/web`."""
    app.mount("/web", StaticFiles(directory=WEB_DIR, check_dir=False), name="web")

    @app.get("/", include_in_schema=False)
    async def page() -> FileResponse:
        return FileResponse(WEB_DIR / "index.html", media_type="text/html", headers=NO_STORE)
