"""`shockbench verify`: walk every lane's result chain in the service's database, recomputing each
result's hash (service.store.result_chain), and name the first record altered after it was stored; compare
the chains' ends with the lanes' checkpoints of their heads (service.store.chain_anchor), so that removing
the newest results is named too.

Checkpoints compared: the database's own (`chain_checkpoints`: on a central database, those the lanes
pushed), the heads log of the data directory when the database is the data directory's (or the log
`--heads` names), and with `--central URL` those on the central database.

Exit 0 with "N results in M lanes verified" when every chain holds; exit 1 with one line naming the first
altered record (its lane and job, and the field that changed when it can tell) or the missing links when one
does not; exit 2 for bad input (no database, old schema, a --heads file that is not there)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from service.cli.db import add_database_arguments, open_database
from service.cli.errors import EXIT_FAILED, CliError

if TYPE_CHECKING:
    from service.store.chain_anchor import Checkpoint


def heads_log(args: argparse.Namespace) -> Path | None:
    """The heads log to compare with: --heads, else the data directory's when its database is read."""
    from service.store.chain_anchor import HEADS_FILE

    if args.heads is not None:
        if not Path(args.heads).is_file():
            raise CliError(f"heads log {args.heads!r} does not exist")
        return Path(args.heads)
    default = Path(args.data) / HEADS_FILE
    return default if args.database is None and default.is_file() else None


def outside_checkpoints(args: argparse.Namespace) -> list[Checkpoint]:
    """The checkpoints of the heads log and, with --central, of the central database."""
    from service.store.chain_anchor import HeadLog, stored_checkpoints

    found: list[Checkpoint] = []
    path = heads_log(args)
    if path is not None:
        logged, unreadable = HeadLog(path).checkpoints()
        if unreadable:
            print(
                f"heads log {path}: {unreadable} unreadable line(s) skipped (a write cut off?)",
                file=sys.stderr,
            )
        found += logged
    if args.central is not None:
        central = open_database(args.central, args.data)
        try:
            with central.sessions() as session:
                found += stored_checkpoints(session, args.lane, "the central database's checkpoint")
        finally:
            central.dispose()
    return found


def run_verify(args: argparse.Namespace) -> int:
    from service.store.result_chain import verify_chain

    checkpoints = outside_checkpoints(args)
    database = open_database(args.database, args.data)
    try:
        report = verify_chain(database, lane=args.lane, checkpoints=checkpoints)
    finally:
        database.dispose()
    if args.lane is not None and report.lanes == 0:
        raise CliError(f"lane {args.lane!r} has no stored results in database {database.safe_url}")
    if report.problem is not None:
        print(report.problem)
        return EXIT_FAILED
    verified = f"{report.results} results in {report.lanes} lane{'s' if report.lanes != 1 else ''} verified"
    if report.checkpoints:
        verified += f", their heads against {report.checkpoints} checkpoints"
    print(verified)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "verify",
        help="check that no stored result was altered or removed (the lanes' result chains)",
        description="Walk every lane's result chain, recompute each result's hash and name the first "
        "record altered or removed since it was stored (exit 1), comparing the chains' ends with the lanes' "
        "checkpoints of their heads; else say how many were verified.",
    )
    add_database_arguments(p)
    p.add_argument("--lane", default=None, help="only this lane's chain")
    p.add_argument(
        "--heads",
        default=None,
        metavar="FILE",
        help="a lane's heads log to compare with (default: the data directory's, when no --database)",
    )
    p.add_argument(
        "--central", default=None, metavar="URL", help="also compare with the central database's checkpoints"
    )
    p.set_defaults(handler=run_verify)
