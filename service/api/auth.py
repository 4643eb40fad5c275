"""`require(role)`: the FastAPI dependency that admits a request carrying `Authorization: Bearer KEY` of
at least that role (401 without a usable key, 403 when the role is too low)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from service.access import KeyRing, Principal, Role
from service.api.errors import ApiError

bearer = HTTPBearer(
    auto_error=False,
    description="A key from the keys file (or the operator key `shockbench serve` printed at start-up).",
)

CHALLENGE = {"WWW-Authenticate": "Bearer"}
NO_KEY = "this needs a key: send 'Authorization: Bearer KEY'"
UNKNOWN_KEY = "unknown key"
KEY_CHECKS: dict[Callable[..., Awaitable[Principal]], Role] = {}
"""Every dependency `require` made, with its role: service.api.key_gate finds the routes that need a key
by them, to refuse anonymous callers before their body is read."""


def require(role: Role) -> Callable[..., Awaitable[Principal]]:
    """A dependency admitting keys of `role` or higher. Async and in-memory: it adds nothing measurable
    to a request."""

    async def admitted(
        request: Request, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)]
    ) -> Principal:
        if credentials is None:
            raise ApiError(401, NO_KEY, headers=CHALLENGE)
        keys: KeyRing = request.app.state.services.keys
        principal = keys.lookup(credentials.credentials)
        if principal is None:
            raise ApiError(401, UNKNOWN_KEY, headers=CHALLENGE)
        if principal.role < role:
            raise ApiError(
                403, f"this needs the {role.label} role; the key has the {principal.role.label} role"
            )
        return principal

    admitted.__name__ = f"require_{role.label}"
    KEY_CHECKS[admitted] = role
    return admitted


Viewer = Annotated[Principal, Depends(require(Role.VIEWER))]
Operator = Annotated[Principal, Depends(require(Role.OPERATOR))]
Admin = Annotated[Principal, Depends(require(Role.ADMIN))]
