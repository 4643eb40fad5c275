"""Entry point of the `shockbench` console script.

Each subcommand lives in its own module with a `register(subparsers)` function that adds its parser and sets
`handler` (a function of the parsed arguments returning an exit code). What a handler raises is mapped in one
place, service.cli.errors.run_command: bad input (UserError, OSError) is one line on stderr and exit code 2;
anything else is a bug, exit code 1 with its traceback in a log file the message names.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys
from collections.abc import Sequence
from types import ModuleType

from service.cli.errors import run_command

COMMAND_MODULES: dict[str, str] = {
    "simulate": "simulate",
    "identify": "identify",
    "fit-tanh": "identify",
    "demo": "identify",
    "diagnose": "diagnose",
    "validate": "validate",
    "sim-devices": "devices",
    "probe": "devices",
    "config": "config",
    "sweep": "sweep",
    "export": "export",
    "report": "report",
    "serve": "serve",
    "db": "db",
    "history": "history",
    "verify": "verify",
    "reanalyse": "reanalyse",
    "archive": "archive",
    "retention": "retention",
}
"""Each command and the module under service/cli that registers it, in `--help`'s order. A command line
that names a command imports and registers only that module: all twelve parsers cost a whole `identify`
about 30 ms of its ~190 ms (tests/service/test_cli_lazy_imports.py checks the table against the parsers)."""


def _modules(names: Sequence[str]) -> list[ModuleType]:
    unique = dict.fromkeys(names)
    return [importlib.import_module(f"service.cli.{name}") for name in unique]


class VersionAction(argparse.Action):
    """`--version`: argparse's own action wants the text when the parser is built; this one looks it up
    only when asked (service.version: importlib.metadata, else the source tree's pyproject.toml), so that no
    other command line pays for importlib.metadata."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: object) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=kwargs.get("help"))

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        from service.version import shockbench_version

        print(f"shockbench {shockbench_version()}")  # on stdout, as argparse's own version action does
        parser.exit()


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The `shockbench` parser with every command, or with only `command`'s module when it is a known one."""
    parser = argparse.ArgumentParser(
        prog="shockbench",
        description="On-vehicle shock absorber test bench: identify the damper force-velocity curve "
        "from laser displacement measurements.",
    )
    parser.add_argument("--version", action=VersionAction, help="print shockbench's version and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    names = [COMMAND_MODULES[command]] if command in COMMAND_MODULES else list(COMMAND_MODULES.values())
    for module in _modules(names):
        module.register(sub)
    return parser


SHORT_LIVED_COMMANDS = frozenset({"identify", "diagnose", "validate", "simulate", "demo", "fit-tanh"})
"""Commands that run one computation and exit: their allocator keeps freed memory (service.allocator),
and their objects are frozen before the interpreter's shutdown."""


def main(argv: Sequence[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    # as the console script's process (argv None), not as a function called by a process that goes on (tests)
    short_lived = argv is None and bool(arguments) and arguments[0] in SHORT_LIVED_COMMANDS
    if short_lived:
        from service.allocator import keep_freed_memory

        keep_freed_memory()
    parser = build_parser(arguments[0] if arguments else None)
    args = parser.parse_args(arguments)
    code = run_command(args.command, lambda: args.handler(args))
    if short_lived:
        # the process ends next: Python's shutdown collects cyclic garbage over every object it holds, about
        # 12 ms of a 170 ms identify; frozen objects are skipped (files are closed already, atexit still runs)
        gc.freeze()
    return code


if __name__ == "__main__":
    sys.exit(main())
