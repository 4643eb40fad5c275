"""InputError, the service's refusal of submitted input, in a module of its own: the CLI's checks
(service.jobs.bounds, run by `shockbench identify`) raise it without importing the job context and the
worker's messages (a few ms of a whole identify). service.jobs.context re-exports it."""

from __future__ import annotations

from estimator.errors import UserError


class InputError(UserError, ValueError):
    """Submitted input that cannot run; `field` names the form field to blame (the API's 422 names it)."""

    def __init__(self, field: str | None, message: str) -> None:
        super().__init__(message, field=field)
