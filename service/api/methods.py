"""The methods a path allows, answered right: OPTIONS and the Allow header of a 405.

Starlette matches routes one by one, and a path served by several routes (GET /jobs and POST /jobs are two
routes) answers a wrong method with the Allow header of the first route whose path matched, and OPTIONS with
405. `AllowedMethods` (pure ASGI middleware) collects the methods of every route whose path matches:
OPTIONS is answered 204 with that Allow header (OPTIONS itself included), and the Allow
header of any 405 is replaced by the full list. Paths no route serves go on to their 404.
"""

from __future__ import annotations

from starlette.routing import BaseRoute, Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send

CANDIDATES = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE")


def allowed_methods(routes: list[BaseRoute], scope: Scope) -> set[str]:
    """Every method some route serves at the request's path (empty: no route has that path). Each
    candidate method is matched as a request of its own, so routers nested in routers (FastAPI keeps
    included routers as branches) answer for their routes."""
    allowed = {
        method
        for method in CANDIDATES
        if any(route.matches({**scope, "method": method})[0] is Match.FULL for route in routes)
    }
    if allowed:
        allowed.add("OPTIONS")
    return allowed


def allow_header(methods: set[str]) -> str:
    return ", ".join(sorted(methods))


class AllowedMethods:
    def __init__(self, app: ASGIApp, routes: list[BaseRoute]) -> None:
        self.app = app
        self.routes = routes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if scope["method"] == "OPTIONS":
            allowed = allowed_methods(self.routes, scope)
            if allowed:
                await send(
                    {
                        "type": "http.response.start",
                        "status": 204,
                        "headers": [(b"allow", allow_header(allowed).encode())],
                    }
                )
                await send({"type": "http.response.body", "body": b""})
                return

        async def fix_allow(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] == 405:
                allowed = allowed_methods(self.routes, scope)
                if allowed:
                    headers = [(k, v) for k, v in message.get("headers", []) if k.lower() != b"allow"]
                    headers.append((b"allow", allow_header(allowed).encode()))
                    message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, fix_allow)
