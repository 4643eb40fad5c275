"""Settings declared once: a dataclass field's default with its unit, bounds and help text, as field
metadata (`setting`), read back with `declared`.

The estimator's settings (the sweep's, differential evolution's) are plain dataclasses so that every layer
may use them; what a user may give for each (its accepted range, its help text) is declared beside the
field instead of in each surface. The service derives from it the API's pydantic models, the CLI's
arguments and their help (service.declarations); tests/test_declarations_agree.py checks that those
surfaces agree. Standard library only (the estimator's layer rule): no pydantic here.
"""

from __future__ import annotations

from dataclasses import MISSING, Field, dataclass, field, fields, is_dataclass
from typing import Any, get_type_hints

DECLARED = "shockbench.declared"
"""The field metadata key that holds a field's Declared."""


@dataclass(frozen=True)
class Declared:
    """What a setting is: its help text, unit and the range a user may give (None: unbounded that way).
    `note` is said after the unit ("the bench envelope limits it")."""

    help: str
    unit: str = ""
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    note: str = ""

    def description(self) -> str:
        """The help text with its unit and note, as the API's schema says it: "sweep start (Hz)"."""
        text = f"{self.help} ({self.unit})" if self.unit else self.help
        return f"{text}; {self.note}" if self.note else text

    def bounds(self) -> dict[str, float]:
        """The bounds given, by pydantic's names (ge, gt, le, lt)."""
        found = {"ge": self.ge, "gt": self.gt, "le": self.le, "lt": self.lt}
        return {name: value for name, value in found.items() if value is not None}

    def admits(self, value: float) -> bool:
        """Whether `value` lies within the bounds (NaN does not)."""
        checks = (
            self.ge is None or value >= self.ge,
            self.gt is None or value > self.gt,
            self.le is None or value <= self.le,
            self.lt is None or value < self.lt,
        )
        return all(checks) and value == value

    def range_text(self, scale: float = 1.0) -> str:
        """The bounds in words, "[0, 1000]" or "(0, 1]" or ">= 1" (values times `scale`)."""
        low = self.ge if self.ge is not None else self.gt
        high = self.le if self.le is not None else self.lt
        if low is not None and high is not None:
            left, right = "[" if self.ge is not None else "(", "]" if self.le is not None else ")"
            return f"{left}{number_text(low * scale)}, {number_text(high * scale)}{right}"
        if low is not None:
            return f"{'>=' if self.ge is not None else '>'} {number_text(low * scale)}"
        if high is not None:
            return f"{'<=' if self.le is not None else '<'} {number_text(high * scale)}"
        return ""


def number_text(value: float) -> str:
    """A bound or default as a person writes it: 2147483647, 0.004, 1e-06 (every digit of a whole number)."""
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    return f"{value:g}"


def setting(
    default: Any,
    help: str,
    *,
    unit: str = "",
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    note: str = "",
) -> Any:
    """A dataclass field with its default and its Declared (unit, bounds, help) as metadata."""
    return field(default=default, metadata={DECLARED: Declared(help, unit, ge, gt, le, lt, note)})


@dataclass(frozen=True)
class DeclaredField:
    """One declared field of a dataclass: its name, type, default and declaration."""

    name: str
    type: Any
    default: Any
    declared: Declared


def declared(cls: type, names: tuple[str, ...] | None = None) -> tuple[DeclaredField, ...]:
    """The declared fields of dataclass `cls` in order (those of `names` only, in that order, when given);
    a field without a declaration is a TypeError (a surface would have nothing to derive)."""
    if not is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    by_name: dict[str, Field[Any]] = {f.name: f for f in fields(cls)}
    hints = get_type_hints(cls)
    found = []
    for name in names if names is not None else tuple(by_name):
        f = by_name[name]
        if DECLARED not in f.metadata:
            raise TypeError(f"{cls.__name__}.{name} has no declaration (estimator.declared.setting)")
        default = f.default if f.default is not MISSING else None
        found.append(DeclaredField(name, hints[name], default, f.metadata[DECLARED]))
    return tuple(found)
