"""The key is checked before the body is read (`KeyGate`), and each route's body cap is known up front.

FastAPI reads and parses a request's body before it solves the route's dependencies, the key check among
them: an anonymous 40 MB POST used to be read to its end (and parsed) only to be answered 401 or 422,
and five of them at once held the event loop the emergency stop shares. `KeyGate` (pure ASGI middleware,
in front of everything that reads a body) finds the route a request is for; when that route needs a key
(it depends on a `service.api.auth.require` check) and the request carries no known Bearer key, it answers
401 at once, with `Connection: close` when a body was announced, so that uvicorn drops the unread body
with the connection instead of reading it to its end. Role checks (403) stay in the routes' dependencies.

What stays open without a key: the operator page (`/`, `/web/...`), the API docs (`/docs`, its assets
under `/docs/assets/`) and the OpenAPI schema (`/api/v1/openapi.json`), none of which takes a body, and the
probes `/healthz` and `/readyz` (service.api.routes.health), exempt here by name (`EXEMPT_PATHS`): a
supervisor polls them every few seconds, so they skip the route table and the key look-up altogether.
Every route under /api/v1 needs a key; /metrics needs one unless its setting opens it (service.api.metrics).
A path no route serves, or a method the path does not take, goes on to its 404 or 405 (neither reads the
body; `service.api.limits.BodyDeadline` closes the connection behind it).

The gate also tells the body cap (`service.api.limits.BodySizeLimit`) which limit applies: the upload
limit for the routes that take a multipart upload (POST /jobs, /diagnoses, /validations), the JSON limit
for every other route (`RoutePolicy` in the request's scope).
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from fastapi import params
from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute, iter_route_contexts
from starlette.requests import Request
from starlette.routing import BaseRoute, compile_path
from starlette.types import ASGIApp, Receive, Scope, Send

from service.access import KeyRing
from service.api.auth import CHALLENGE, KEY_CHECKS, NO_KEY, UNKNOWN_KEY, bearer
from service.api.errors import error_response
from service.api.routes.health import HEALTH_PATH, READY_PATH

POLICY_SCOPE_KEY = "shockbench.route_policy"
"""Where the gate leaves a request's `RoutePolicy` for the middleware inside it."""


@dataclass(frozen=True)
class RoutePolicy:
    needs_key: bool = False
    """The route depends on a key check (service.api.auth.require)."""
    upload: bool = False
    """The route takes a multipart upload: the upload limit applies, else the JSON limit."""


OPEN = RoutePolicy()
"""A request no key-checked route serves: the page, the docs, the schema, a 404 or a 405."""
EXEMPT_PATHS = frozenset({HEALTH_PATH, READY_PATH})
"""The probes: open to anyone, answered without a look at the route table (see the module docstring)."""


def announces_body(scope: Scope) -> bool:
    """The request's headers say a body follows (a Content-Length above 0, or chunked)."""
    for name, value in scope.get("headers") or ():
        if name == b"transfer-encoding":
            return True
        if name == b"content-length":
            return value.strip() not in (b"0", b"")
    return False


def declared_length(scope: Scope) -> int | None:
    """The request's Content-Length in bytes: None when it declares none, -1 when it is not a whole number
    of bytes (malformed or negative)."""
    declared = dict(scope.get("headers") or []).get(b"content-length")
    if declared is None:
        return None
    try:
        return max(int(declared), -1)
    except ValueError:
        return -1


def _calls(dependant: Dependant) -> Iterator[object]:
    for dependency in dependant.dependencies:
        yield dependency.call
        yield from _calls(dependency)


def policy_of_route(route: APIRoute) -> RoutePolicy:
    return RoutePolicy(
        needs_key=any(call in KEY_CHECKS for call in _calls(route.dependant)),
        upload=any(isinstance(p.field_info, params.Form) for p in route.dependant.body_params),
    )


@dataclass(frozen=True)
class _Entry:
    path: re.Pattern[str]
    methods: frozenset[str]
    policy: RoutePolicy


def route_table(routes: Sequence[BaseRoute]) -> list[_Entry]:
    """Every FastAPI route (included routers flattened, paths with their prefix) with its policy."""
    table = []
    for context in iter_route_contexts(routes):
        route = context.original_route
        if isinstance(route, APIRoute) and context.path:
            pattern = compile_path(context.path)[0]
            table.append(_Entry(pattern, frozenset(context.methods or ()), policy_of_route(route)))
    return table


class KeyGate:
    """Pure ASGI middleware: 401 before the body for the routes that need a key. `routes` is the app's
    route list (read at the first request, and again whenever routes were added)."""

    def __init__(self, app: ASGIApp, routes: Sequence[BaseRoute], keys: KeyRing) -> None:
        self.app = app
        self.routes = routes
        self.keys = keys
        self._table: list[_Entry] = []
        self._table_of = -1

    def policy(self, scope: Scope) -> RoutePolicy:
        path, method = scope["path"], scope["method"]
        if path in EXEMPT_PATHS:
            return OPEN
        if self._table_of != len(self.routes):
            self._table, self._table_of = route_table(self.routes), len(self.routes)
        for entry in self._table:
            if method in entry.methods and entry.path.match(path):
                return entry.policy
        return OPEN

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        policy = self.policy(scope)
        scope[POLICY_SCOPE_KEY] = policy
        if policy.needs_key:
            refusal = await self.refusal(scope)
            if refusal is not None:
                headers = dict(CHALLENGE)
                if announces_body(scope):
                    headers["Connection"] = "close"  # uvicorn drops the unread body with the connection
                await error_response(401, "unauthorized", refusal, headers=headers)(scope, receive, send)
                return
        await self.app(scope, receive, send)

    async def refusal(self, scope: Scope) -> str | None:
        """Why the request's key is refused (the messages of service.api.auth), None for a known key. The
        header is read by the same HTTPBearer as the routes' checks; the look-up is in memory."""
        credentials = await bearer(Request(scope))
        if credentials is None:
            return NO_KEY
        if self.keys.lookup(credentials.credentials) is None:
            return UNKNOWN_KEY
        return None
