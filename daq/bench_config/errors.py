"""The bench configuration's one error, and how a pydantic validation error becomes it: one line naming
the key (a path into the TOML document) and what is wrong with it."""

from __future__ import annotations

from typing import Any

from pydantic import ValidationError

from estimator.errors import UserError

Key = tuple[str | int, ...]
"""A path into the TOML document: ("lasers", 1, "channel") is the channel of the second [[lasers]] table."""

TOP_LEVEL = {"bench": "[bench]", "exciter": "[exciter]", "lasers": "[[lasers]]"}
"""The file's top-level tables, as their headers are written."""

TYPE_WORDS = {
    "string_type": "a string",
    "int_type": "an integer",
    "float_type": "a number",
    "bool_type": "true or false",
    "model_type": "a table",
    "dataclass_type": "a table",
    "dict_type": "a table",
    "model_attributes_type": "a table",
    "list_type": "an array of tables ([[lasers]])",
    "tuple_type": "an array of tables ([[lasers]])",
}
"""pydantic's type errors, in the words of a TOML file."""

BOUND_WORDS = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<", "less_than_equal": "<="}
"""pydantic's bound errors: the comparison each one failed."""

MISSING = ("missing", "missing_argument")
UNKNOWN = ("extra_forbidden", "unexpected_keyword_argument")


class BenchConfigError(UserError, ValueError):
    """A bench configuration that cannot be used. `key` is where the problem is, as a path into the TOML
    document (("lasers", 1, "channel") is the channel of the second [[lasers]] table), when known."""

    def __init__(self, message: str, key: Key = ()) -> None:
        super().__init__(message)
        self.message = message
        self.key = key

    @property
    def field(self) -> str | None:  # type: ignore[override]
        """The key as a dotted path ("lasers.1.channel"), the field to blame."""
        return ".".join(str(part) for part in self.key) or None


def from_validation(
    exc: ValidationError, known_keys: dict[str, tuple[str, ...]], *, located: bool
) -> BenchConfigError:
    """The first problem pydantic found (a top-level table before the keys in tables, an unknown key before
    the others, a missing key last), as a
    BenchConfigError with its key. `known_keys`: the keys of each
    table ("bench", "envelope", "exciter", "lasers"), named when a key is unknown. `located`: the error is
    shown after its file, line and key (a file); otherwise (an object built in code) a type or bound error
    names its field itself."""
    errors = exc.errors()
    # the file's tables first; then as a reader goes through a table: a misspelt key first (it explains
    # the missing one), then bad values
    error = min(errors, key=lambda e: (len(e["loc"]) > 1, e["type"] not in UNKNOWN, e["type"] in MISSING))
    loc: Key = tuple(error["loc"])
    kind: str = error["type"]
    cause = error.get("ctx", {}).get("error")
    if isinstance(cause, BenchConfigError):
        return BenchConfigError(cause.message, (*loc, *cause.key))
    if kind in MISSING:
        if len(loc) == 1 and loc[0] in TOP_LEVEL and located:
            return BenchConfigError(f"missing {TOP_LEVEL[str(loc[0])]} table")
        return BenchConfigError(f"missing key {loc[-1]!r}", loc[:-1])
    if kind in UNKNOWN:
        return BenchConfigError(_unknown(loc, known_keys), loc)
    message = _problem(kind, error)
    if not located and loc:
        message = f"{loc[-1]} {message}"
    return BenchConfigError(message, loc)


def _unknown(loc: Key, known_keys: dict[str, tuple[str, ...]]) -> str:
    if len(loc) == 1:
        return f"unknown table or key {loc[0]!r} (expected {', '.join(TOP_LEVEL.values())})"
    table = next((str(part) for part in reversed(loc[:-1]) if isinstance(part, str)), "")
    expected = known_keys.get(table, ())
    return f"unknown key {loc[-1]!r}" + (f" (expected one of {', '.join(expected)})" if expected else "")


def _problem(kind: str, error: Any) -> str:
    value = error.get("input")
    if kind in TYPE_WORDS:
        return f"must be {TYPE_WORDS[kind]}, got {value!r}"
    if kind in BOUND_WORDS:
        bound = next(iter(error.get("ctx", {}).values()), "?")
        return f"must be {BOUND_WORDS[kind]} {bound}, got {value!r}"
    cause = error.get("ctx", {}).get("error")
    return str(cause).splitlines()[0] if cause is not None else str(error["msg"])
