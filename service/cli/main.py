"""Entry point of the `shockbench` console script.

Each subcommand lives in its own module with a `register(subparsers)` function that adds its parser and sets
`handler` (a function of the parsed arguments returning an exit code). Errors the user can fix (CliError,
ValueError, OSError, KeyError from input files) become one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from service.cli import devices, diagnose, export, identify, serve, simulate, sweep, validate
from service.cli.errors import EXIT_BAD_INPUT, CliError

MODULES = (simulate, identify, diagnose, validate, devices, sweep, export, serve)


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
    try:
        return int(args.handler(args))
    except KeyboardInterrupt:
        print("shockbench: interrupted", file=sys.stderr)
        return 130
    except (CliError, ValueError, OSError, KeyError) as exc:
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"shockbench {args.command}: error: {message}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
