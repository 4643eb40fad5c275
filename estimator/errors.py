"""The root of every "bad input" error in shockbench, and the one helper that makes an exception one line.

Why here, in the estimator: the estimator is the one package every other package may import (and it imports
nothing of ours outside estimator/), so a root defined here is visible to drivers, daq, simulators and
service alike without any import pointing upward. The estimator's own bad-input errors (a model file, an
undersampled recording) need the root too.

The contract (issue 16): an exception that is a `UserError` is input the user can fix; its message is one
line naming the problem, and `field` names the offending field when there is one. The edges map it once:
the CLI to exit code 2 (service/cli/main.py), the API to an HTTP status by one table (service/api/errors.py),
the worker to a failed job with that line as its reason. Any other exception is a bug: the edges log its
traceback under an error id and say where to find it.
"""

from __future__ import annotations


class UserError(Exception):
    """Bad input the user can fix: a file, a frame, an option, a request. `field` names the offending
    field (a form field, an option, a TOML key) when there is one, else None.

    Existing error classes keep their other bases (many are also ValueError) so that code catching those
    still works; the root is what the edges test for."""

    field: str | None = None

    def __init__(self, *args: object, field: str | None = None) -> None:
        super().__init__(*args)
        if field is not None:
            self.field = field


class NotFoundError(UserError):
    """The request names a thing that does not exist (a job, a sweep, a file of a job)."""


class ConflictError(UserError):
    """The request is well formed but the state forbids it now (a busy bench, a sweep not yet ended)."""


def one_line(exc: BaseException) -> str:
    """The first non-empty line of an exception's message, or its class name when it has none."""
    lines = [line for line in str(exc).strip().splitlines() if line.strip()]
    return lines[0].strip() if lines else type(exc).__name__


class InvalidValueError(UserError, ValueError):
    """A value outside its domain in a type built from user input (sweep settings, vehicle parameters, a
    recording, identify options): a negative mass, a zero duration. Also a ValueError, as these checks
    were before the root existed and callers catch them as such."""
