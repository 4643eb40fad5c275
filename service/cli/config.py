"""`shockbench config`: the bench configuration file's JSON Schema, and a check of one file.

    shockbench config schema > bench.schema.json     # for editors (Taplo, Even Better TOML, ...)
    shockbench config check BENCH.toml               # "BENCH.toml: OK ..." and exit 0, or one line, exit 2

Both come from the one declaration of the file (daq.bench_config): the schema is generated from it and the
check is the reader `sweep`, `probe` and `serve` use, so a file that passes here loads there. A bad file is
one line naming the file, the line and the key, exit 2. Examples of every supported combination of devices
are in examples/ (docs/configuration.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from service.cli.errors import CliError


def run_schema(args: argparse.Namespace) -> int:
    import json

    from daq.bench_config import bench_config_schema

    print(json.dumps(bench_config_schema(), indent=2))
    return 0


def run_check(args: argparse.Namespace) -> int:
    from daq.bench_config import load_bench_config

    path: Path = args.file
    if not path.is_file():
        raise CliError(f"{path}: no such bench configuration")
    config = load_bench_config(path)
    print(
        f"{path}: OK, bench {config.name!r} ({config.model.value}, {config.exciter.kind} drive, "
        f"{len(config.lasers)} laser{'s' if len(config.lasers) != 1 else ''})"
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "config",
        help="the bench configuration: print its JSON Schema, or check a file",
        description="The bench configuration file (TOML): `schema` prints its JSON Schema for editors, "
        "`check FILE` reads a file as sweep, probe and serve do (exit 0 when it is valid, 2 with one line "
        "naming the file, line and key when not).",
    )
    actions = parser.add_subparsers(dest="config_action", required=True, metavar="ACTION")
    schema = actions.add_parser("schema", help="print the bench configuration's JSON Schema")
    schema.set_defaults(handler=run_schema)
    check = actions.add_parser("check", help="check a bench configuration file")
    check.add_argument("file", type=Path, metavar="FILE", help="bench configuration (TOML)")
    check.set_defaults(handler=run_check)
