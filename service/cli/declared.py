"""The CLI's options derived from the estimator's declared settings (estimator.declared): each option's
name, default, unit, range and help come from the setting's one declaration, as the API's fields do
(service.declarations), and the range is checked when the command runs (one line, exit 2).

An option is the field's name in lower case with dashes (`start_Hz` is `--start-hz`); `Shown` puts a
field in another unit (`amplitude_m` as `--amplitude-mm`, scale 1000). Light: the declarations import only
the standard library, so that `shockbench --help` stays fast."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from enum import Enum
from typing import Any

from estimator.declared import DeclaredField, declared, number_text
from service.cli.errors import CliError


@dataclass(frozen=True)
class Option:
    """One declared field as a command-line option: its flag, argparse destination, unit and scale."""

    field: DeclaredField
    flag: str
    unit: str
    scale: float
    kind: type | None = None
    """The option's type when it is not the field's (a size in MiB of a field in bytes: float)."""

    @property
    def dest(self) -> str:
        return self.flag.removeprefix("--").replace("-", "_")

    @property
    def is_choice(self) -> bool:
        return isinstance(self.field.type, type) and issubclass(self.field.type, Enum)

    def default(self) -> Any:
        value = self.field.default
        if isinstance(value, Enum):
            return value.value
        if self.scale == 1.0:
            return value
        return round(value * self.scale) if self.kind is int else value * self.scale

    def help(self) -> str:
        d = self.field.declared
        default = self.default()
        shown = number_text(default) if _number(default) else str(default)
        parts = [self.unit, d.range_text(self.scale), f"default {shown}"]
        inside = "; ".join(part for part in parts if part)
        return f"{d.help} ({inside})" if inside else d.help

    def value(self, args: argparse.Namespace) -> Any:
        """The field's value from the parsed arguments (in the field's unit), its range checked."""
        given = getattr(args, self.dest)
        if self.is_choice:
            return self.field.type(given)
        value = given / self.scale if self.scale != 1.0 else given
        if not self.field.declared.admits(value):
            raise CliError(f"{self.flag} must {self.bounds_words()}")
        return int(value) if self.field.type is int else value

    def bounds_words(self) -> str:
        """What a value of the option must do: lie in [0, 1000], be at least 1, be > 0."""
        text = self.field.declared.range_text(self.scale)
        if text.startswith(("[", "(")):
            return f"lie in {text}"
        relation, _, bound = text.partition(" ")
        words = {">=": "be at least", "<=": "be at most", ">": "be >", "<": "be <"}
        return f"{words[relation]} {bound}"


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


@dataclass(frozen=True)
class Shown:
    """How an option shows a field in another unit than the field's: `--amplitude-mm` for amplitude_m is
    Shown("mm", 1000.0); `--max-upload-mb` for max_upload_bytes is Shown("MiB", 2**-20, float, "mb")."""

    unit: str
    scale: float = 1.0
    kind: type | None = None
    """The option's type (default the field's)."""
    suffix: str = ""
    """The unit as the flag ends (default the unit in lower case)."""


def options(cls: type, names: tuple[str, ...], shown: dict[str, Shown] | None = None) -> list[Option]:
    """The options of the declared fields `names` of `cls`; `shown`: field -> its unit on the command line."""
    found = []
    for f in declared(cls, names):
        how = (shown or {}).get(f.name)
        if how is None:
            found.append(Option(f, "--" + f.name.lower().replace("_", "-"), f.declared.unit, 1.0))
            continue
        stem = f.name.removesuffix(f"_{f.declared.unit}") if f.declared.unit else f.name
        flag = "--" + f"{stem}_{how.suffix or how.unit}".lower().replace("_", "-")
        found.append(Option(f, flag, how.unit, how.scale, how.kind))
    return found


def add_options(parser: argparse.ArgumentParser, found: list[Option]) -> None:
    """Add each option to `parser`: its type, default, choices and help from the declaration."""
    for option in found:
        if option.is_choice:
            choices = [member.value for member in option.field.type]
            parser.add_argument(option.flag, choices=choices, default=option.default(), help=option.help())
        else:
            kind = option.kind or _plain_number(option.field.type)
            parser.add_argument(option.flag, type=kind, default=option.default(), help=option.help())


def _plain_number(annotation: Any) -> type:
    """int for `int` or `int | None` (a seed), else float."""
    return int if annotation is int or int in getattr(annotation, "__args__", ()) else float


def values(args: argparse.Namespace, found: list[Option]) -> dict[str, Any]:
    """field name -> value, for the dataclass (CliError naming the option when out of range)."""
    return {option.field.name: option.value(args) for option in found}
