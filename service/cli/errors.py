"""How the CLI ends a command that raised, in one place (`run_command`):

- a `UserError` (estimator.errors: bad input the user can fix) or an `OSError` (a file missing or not
  readable, a port that will not open: the machine's state, which the user fixes too) prints one line on
  stderr and exits 2;
- anything else is a bug: one line on stderr naming a log file that holds the traceback, exit 1. The
  traceback is never lost and never shown raw to the user.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path

from estimator.errors import UserError, one_line


class CliError(UserError):
    """A problem the user can fix (bad file, bad option); its message is printed as one line."""


EXIT_BAD_INPUT = 2
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130

LOG_DIR_ENV = "SHOCKBENCH_LOG_DIR"
"""Where bug reports (tracebacks) go; the system's temporary directory when unset."""


def bug_log_dir() -> Path:
    import tempfile  # here and below: only when a bug is reported (every command imports this module)

    return Path(os.environ.get(LOG_DIR_ENV) or tempfile.gettempdir())


def write_bug_log(command: str, exc: BaseException) -> Path:
    """Write the traceback of `exc` to a new file named by a fresh error id; returns its path. The file is
    the user's alone (0600, whatever the umask), unlike the outputs the user asks for: it lands in a shared
    temporary directory, and the command line and the traceback's values may hold a secret (a database URL
    with its password)."""
    import datetime as dt
    import secrets
    import traceback

    error_id = secrets.token_hex(6)
    folder = bug_log_dir()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"shockbench-error-{error_id}.log"
    when = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    text = "".join(traceback.format_exception(exc))
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with open(descriptor, "w", encoding="utf-8") as log:
        log.write(
            f"error id {error_id}\ncommand: shockbench {command}\nargv: {sys.argv!r}\ntime: {when}\n\n{text}"
        )
    return path


def run_command(command: str, handler: Callable[[], int], *, say_interrupted: bool = True) -> int:
    """Run a subcommand's handler and map what it raised to a message and an exit code (see the module
    docstring). `command` names the subcommand in messages."""
    try:
        return int(handler())
    except KeyboardInterrupt:
        if say_interrupted:
            print("shockbench: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (UserError, OSError) as exc:
        print(f"shockbench {command}: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:
        try:
            where = f"the traceback is in {write_bug_log(command, exc)}"
        except OSError as log_error:  # no place for the log: the traceback goes to stderr, not lost
            import traceback

            traceback.print_exception(exc, file=sys.stderr)
            where = f"the traceback is above (no log file: {one_line(log_error)})"
        print(
            f"shockbench {command}: internal error (a bug, not your input): "
            f"{type(exc).__name__}: {one_line(exc)}; {where}",
            file=sys.stderr,
        )
        return EXIT_FAILED
