"""Options whose spelling changed: the one helper every command uses for them.

The CLI spells a unit-bearing option alike in every command, with its unit last (`--amplitude-mm`,
`--duration-s`, `--settle-s`, `--stop-hz`), as the code names its values (`duration_s`). An option that was
spelled otherwise keeps its old spelling as a hidden alias: a script written for it still runs, and each use
prints one line on stderr saying the new spelling (and, where the unit changed, the value converted), so
that the script gets updated. `--help` and the README show the new spelling alone
(tests/service/test_readme_cli.py compares them).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any


class FormerSpelling(argparse.Action):
    """The hidden alias of an option: stores into the new option's destination (the value times `factor`
    when the unit changed) and says the new spelling on stderr."""

    def __init__(
        self,
        option_strings: Sequence[str],
        dest: str,
        *,
        now: str,
        factor: float = 1.0,
        unit: str = "",
        **kwargs: Any,
    ) -> None:
        super().__init__(option_strings, dest, **kwargs)
        self.now = now
        self.factor = factor
        self.unit = unit

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        notice = f"{parser.prog}: {option_string} is now {self.now}"
        if self.factor != 1.0:
            values = values * self.factor
            notice += f" (in {self.unit}: read as {self.now} {values:g})"
        print(notice, file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_option(
    parser: argparse.ArgumentParser,
    name: str,
    *,
    formerly: str,
    factor: float = 1.0,
    unit: str = "",
    **kwargs: Any,
) -> argparse.Action:
    """parser.add_argument(name, **kwargs), and `formerly` accepted for it, hidden from --help, with a notice.
    `factor` converts a value given in the old spelling's unit into the new one's (`--amplitude-m 0.004` is
    `--amplitude-mm 4`: factor 1000, unit "mm"); `type` must then give a number."""
    action = parser.add_argument(name, **kwargs)
    parser.add_argument(
        formerly,
        dest=action.dest,
        type=action.type,
        action=FormerSpelling,
        now=name,
        factor=factor,
        unit=unit,
        default=argparse.SUPPRESS,  # the new option's default stands
        help=argparse.SUPPRESS,
    )
    return action
