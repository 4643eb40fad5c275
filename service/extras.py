"""The optional dependencies (pyproject.toml's extras) and the one line that names the extra to install when
a feature needs a module that is not there.

Why extras: a single bench (SQLite, one lane, the CLI, `serve`) needs neither PostgreSQL's driver nor Dask,
and the test tools are for developers; the core install stays small (`python3 run.py demo`). Code that needs
an extra imports it lazily, where the feature starts, inside `extra_needed`, so that a missing module is bad
input the user fixes by installing the extra (one line, exit code 2 on the CLI), never a traceback.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from estimator.errors import UserError

EXTRAS: dict[str, tuple[str, ...]] = {
    "postgres": ("psycopg",),
    "cluster": ("dask", "distributed"),
}
"""Each extra and the top-level modules it provides (pyproject.toml [project.optional-dependencies])."""


class MissingExtraError(UserError, ImportError):
    """A feature needs an extra that is not installed; the message says which and how to install it. Also an
    ImportError, as what it replaces was."""


def missing_extra_message(extra: str, needed_for: str) -> str:
    """One line: what needs the extra, the modules missing, and the command that installs them."""
    modules = ", ".join(EXTRAS[extra])
    return (
        f"{needed_for} needs shockbench's optional dependencies [{extra}] ({modules}), not installed: "
        f"pip install 'shockbench[{extra}]'"
    )


@contextmanager
def extra_needed(
    extra: str, needed_for: str, error: Callable[[str], UserError] = MissingExtraError
) -> Iterator[None]:
    """Imports (or code that imports) inside this block may miss `extra`'s modules: such a
    ModuleNotFoundError becomes `error` with `missing_extra_message`. Any other missing module is not ours
    to explain and propagates unchanged."""
    try:
        yield
    except ModuleNotFoundError as exc:
        if (exc.name or "").partition(".")[0] not in EXTRAS[extra]:
            raise
        raise error(missing_extra_message(extra, needed_for)) from None


def require_extra(extra: str, needed_for: str) -> None:
    """Fail at once, before any work, when `extra` is not installed; imports nothing (a command checks first
    and imports when it gets there)."""
    with extra_needed(extra, needed_for):
        for module in EXTRAS[extra]:
            if importlib.util.find_spec(module) is None:
                raise ModuleNotFoundError(f"No module named {module!r}", name=module)
