"""Security headers on every response: the page, the API, the docs, the errors (the 401 of the key gate and
the 500 of an unexpected error included).

- Content-Security-Policy. The operator page (service/web/) has no inline script or style, loads its
  modules, styles and nothing else from the service itself and talks only to it: `PAGE_POLICY` allows
  exactly that ('self'), and `frame-ancestors 'none'` keeps it out of other sites' frames (clickjacking the
  emergency stop). The API answers with the same policy (a JSON or SVG answer opened in a browser runs
  nothing either). The docs page (/docs, FastAPI's Swagger UI, served from the package:
  service.api.docs_page) starts Swagger UI with one inline script: it has its own policy allowing that one
  script by its hash (`script_hashes`), so that no other inline script would run there.
- X-Content-Type-Options: nosniff (a download is never sniffed into HTML), Referrer-Policy: no-referrer,
  and X-Frame-Options: DENY for browsers that predate frame-ancestors.

`SecurityHeaders` wraps the whole app (outside FastAPI's error middleware, see service.api.app.ServiceApp):
a header a route set itself (the docs' policy) is kept.
"""

from __future__ import annotations

import base64
import hashlib
import re

from starlette.types import ASGIApp, Message, Receive, Scope, Send

PAGE_POLICY = "; ".join(
    [
        "default-src 'self'",
        "script-src 'self'",
        "style-src 'self'",
        "img-src 'self' data: blob:",
        "connect-src 'self'",
        "object-src 'none'",
        "base-uri 'none'",
        "form-action 'self'",
        "frame-ancestors 'none'",
    ]
)
"""The operator page's policy (also sent with every API answer)."""

HEADERS: dict[str, str] = {
    "content-security-policy": PAGE_POLICY,
    "x-content-type-options": "nosniff",
    "referrer-policy": "no-referrer",
    "x-frame-options": "DENY",
}


def script_hashes(html: str) -> list[str]:
    """The CSP sources ('sha256-...') of the inline scripts of `html` (a page made here, never input)."""
    bodies = re.findall(r"<script>(.*?)</script>", html, flags=re.DOTALL)
    return [
        f"'sha256-{base64.b64encode(hashlib.sha256(body.encode()).digest()).decode()}'" for body in bodies
    ]


class SecurityHeaders:
    """Pure ASGI middleware adding `HEADERS` to every response start (those a response already has are
    kept)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        self.headers = [(name.encode(), value.encode()) for name, value in HEADERS.items()]

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {name.lower() for name, _ in headers}
                headers.extend((name, value) for name, value in self.headers if name not in present)
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, with_headers)
