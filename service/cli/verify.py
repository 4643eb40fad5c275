"""`shockbench verify`: walk every lane's result chain in the service's database, recomputing each
result's hash (service.store.result_chain), and name the first record altered after it was stored.

Exit 0 with "N results in M lanes verified" when every chain holds; exit 1 with one line naming the first
altered record (its lane and job) when one does not; exit 2 for bad input (no database, old schema)."""

from __future__ import annotations

import argparse

from service.cli.db import add_database_arguments, open_database
from service.cli.errors import EXIT_FAILED, CliError


def run_verify(args: argparse.Namespace) -> int:
    from service.store.result_chain import verify_chain

    database = open_database(args.database, args.data)
    try:
        report = verify_chain(database, lane=args.lane)
    finally:
        database.dispose()
    if args.lane is not None and report.lanes == 0:
        raise CliError(f"lane {args.lane!r} has no stored results in database {database.safe_url}")
    if report.problem is not None:
        print(report.problem)
        return EXIT_FAILED
    print(f"{report.results} results in {report.lanes} lane{'s' if report.lanes != 1 else ''} verified")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "verify",
        help="check that no stored result was altered (the lanes' result chains)",
        description="Walk every lane's result chain, recompute each result's hash and name the first "
        "record altered or removed since it was stored (exit 1); else say how many were verified.",
    )
    add_database_arguments(p)
    p.add_argument("--lane", default=None, help="only this lane's chain")
    p.set_defaults(handler=run_verify)
