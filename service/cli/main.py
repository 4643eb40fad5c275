"""Entry point of the `shockbench` console script.

Each subcommand lives in its own module with a `register(subparsers)` function that adds its parser and sets
`handler` (a function of the parsed arguments returning an exit code). What a handler raises is mapped in one
place, service.cli.errors.run_command: bad input (UserError, OSError) is one line on stderr and exit code 2;
anything else is a bug, exit code 1 with its traceback in a log file the message names.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from service.cli import (
    db,
    devices,
    diagnose,
    export,
    history,
    identify,
    reanalyse,
    serve,
    simulate,
    sweep,
    validate,
    verify,
)
from service.cli.errors import run_command

MODULES = (
    simulate,
    identify,
    diagnose,
    validate,
    devices,
    sweep,
    export,
    serve,
    db,
    history,
    verify,
    reanalyse,
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="shockbench",
        description="On-vehicle shock absorber test bench: identify the damper force-velocity curve "
        "from laser displacement measurements.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in MODULES:
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_command(args.command, lambda: args.handler(args))


if __name__ == "__main__":
    sys.exit(main())
