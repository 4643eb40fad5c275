"""Typed JSON errors: every error a client sees is {"error": {"code", "message", "field"?}}, with a one-line
message; a stack trace never leaves the service (it goes to the log).

The one place where domain errors become HTTP: the bench, sweep and job logic raises `UserError`s
(estimator.errors: bad input, a thing not found, a state conflict such as a busy bench) and never an HTTP
status; `DOMAIN_ERRORS` maps each class to its status and code (the most specific class in an exception's
MRO wins). `ApiError` stays for the routes themselves (authentication, a missing job, limits). Any other
exception is a bug: 500 with an error id, logged with its traceback under that id.
"""

from __future__ import annotations

import logging
import secrets
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from daq.storage.hdf5_recording import RecordingFileError, RecordingGapError
from estimator.errors import ConflictError, NotFoundError, UserError, one_line
from service.bench_control import BenchBusyError

log = logging.getLogger("shockbench.api")

CODES = {
    400: "bad_request",
    401: "unauthorized",
    403: "forbidden",
    404: "not_found",
    405: "method_not_allowed",
    406: "not_acceptable",
    408: "request_timeout",
    409: "conflict",
    413: "payload_too_large",
    415: "unsupported_media_type",
    422: "invalid",
    429: "too_many_requests",
    500: "internal",
    503: "unavailable",
}


DOMAIN_ERRORS: dict[type[UserError], tuple[int, str]] = {
    UserError: (422, "invalid"),
    NotFoundError: (404, "not_found"),
    ConflictError: (409, "conflict"),
    BenchBusyError: (409, "bench_busy"),
    RecordingFileError: (422, "bad_recording"),
    RecordingGapError: (422, "recording_gaps"),
}
"""Domain error class -> (HTTP status, error code); a class not listed takes its nearest listed base's."""


def status_of(exc: UserError) -> tuple[int, str]:
    """(HTTP status, error code) of a domain error, by `DOMAIN_ERRORS`."""
    for cls in type(exc).__mro__:
        if cls in DOMAIN_ERRORS:
            return DOMAIN_ERRORS[cls]  # type: ignore[index]
    raise AssertionError("unreachable: UserError is in the table")


class ErrorDetail(BaseModel):
    code: str = Field(description="machine-readable, e.g. invalid, unauthorized, not_found, conflict")
    message: str = Field(description="one line for a person")
    field: str | None = Field(None, description="the request field to blame, when there is one")


class ErrorBody(BaseModel):
    error: ErrorDetail


class ApiError(Exception):
    """Raise anywhere in a request to answer with a typed error."""

    def __init__(
        self,
        status: int,
        message: str,
        *,
        code: str | None = None,
        field: str | None = None,
        headers: dict[str, str] | None = None,
    ) -> None:
        super().__init__(message)
        self.status = status
        self.code = code or CODES.get(status, f"http_{status}")
        self.message = message
        self.field = field
        self.headers = headers


MAX_MESSAGE_CHARS = 300
"""An error message is one line of at most this many characters: input echoed in a message (a header of a
million columns, a 1 MB TOML line) is cut, so an error body stays small whatever was sent."""
MAX_FIELD_CHARS = 80


def clip(text: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """The first line of `text`, cut to `limit` characters with an ellipsis saying how much was left out."""
    line = one_line(Exception(text)) if text.strip() else ""
    if len(line) <= limit:
        return line
    return f"{line[: limit - 30]}... ({len(line) - limit + 30} more characters)"


def error_response(
    status: int, code: str, message: str, field: str | None = None, headers: dict[str, str] | None = None
) -> JSONResponse:
    field = clip(field, MAX_FIELD_CHARS) if field is not None else None
    body = ErrorBody(error=ErrorDetail(code=code, message=clip(message) or code, field=field))
    return JSONResponse(body.model_dump(exclude_none=True), status_code=status, headers=headers)


def responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI documentation of the error answers a route can give."""
    return {s: {"model": ErrorBody, "description": CODES.get(s, "error").replace("_", " ")} for s in statuses}


def _field_of(location: tuple[Any, ...] | list[Any]) -> str | None:
    names = [str(part) for part in location if part not in ("body", "query", "path", "header", "cookie")]
    return ".".join(names) or None


async def _api_error(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ApiError)
    return error_response(exc.status, exc.code, exc.message, exc.field, exc.headers)


async def _user_error(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, UserError)
    status, code = status_of(exc)
    return error_response(status, code, one_line(exc), exc.field)


async def _validation_error(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    errors = list(exc.errors())
    if not errors:
        return error_response(422, "invalid", "invalid request")
    first = errors[0]
    field = _field_of(first.get("loc", ()))
    message = f"{field or 'request body'}: {first.get('msg', 'invalid')}"
    if len(errors) > 1:
        message += f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})"
    return error_response(422, "invalid", message, field)


async def _http_error(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    message = exc.detail if isinstance(exc.detail, str) else str(exc.detail)
    return error_response(
        exc.status_code,
        CODES.get(exc.status_code, f"http_{exc.status_code}"),
        message,
        headers=dict(exc.headers) if exc.headers else None,
    )


async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
    """A bug, not an input the checks foresaw: logged with a fresh error id that the answer carries, so
    that a user's report finds its traceback. `Connection: close` makes the client open a new connection
    for its next request (uvicorn drops this one after an unhandled exception, and a client reusing it
    would see its next request fail too)."""
    error_id = secrets.token_hex(6)
    log.error(
        "error id %s: unexpected error in %s %s", error_id, request.method, request.url.path, exc_info=exc
    )
    return error_response(
        500,
        "internal",
        f"internal error (error id {error_id}); the service log has the details under that id",
        headers={"Connection": "close", "X-Error-Id": error_id},
    )


def install_error_handlers(app: FastAPI) -> None:
    app.add_exception_handler(ApiError, _api_error)
    app.add_exception_handler(UserError, _user_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    app.add_exception_handler(Exception, _unexpected)
