"""How the CLI reports bad input: one line on stderr, a non-zero exit, never a traceback."""

from __future__ import annotations

from estimator.errors import UserError


class CliError(UserError):
    """A problem the user can fix (bad file, bad option); its message is printed as one line."""


EXIT_BAD_INPUT = 2
EXIT_FAILED = 1
