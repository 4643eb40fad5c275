"""`shockbench retention`: the service's retention pass by hand (service.store.retention), e.g. with
--dry-run to see what `serve --retain-days` would delete.

    shockbench retention --data DIR [--database URL] [--retain-days DAYS] [--lane LANE] [--dry-run]

Prints one line per file deleted (or, with --dry-run, that would be) with its size and why, then the total.
Exit 0; 2 for bad input (no database there, an old schema, --retain-days not > 0).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from service.cli.db import add_database_arguments, open_database
from service.cli.errors import CliError

DEFAULT_RETAIN_DAYS = 90.0
"""service.store.retention's DEFAULT_RETAIN_DAYS, named here so that `shockbench --help` does not import
the database layer (tests/service/test_quotas.py checks they are the same)."""


def run_retention_command(args: argparse.Namespace) -> int:
    if not args.retain_days > 0:
        raise CliError("--retain-days must be > 0")
    from service.store.retention import RetentionPolicy, run_retention

    lanes = (args.lane, "") if args.lane is not None else None
    # the data directory's own database only: a database named by URL may be the fleet's archive
    policy = RetentionPolicy(args.retain_days, lanes=lanes, stored_copies=args.database is None)
    database = open_database(args.database, args.data)
    try:
        removals = run_retention(database, Path(args.data), policy, dry_run=args.dry_run)
    finally:
        database.dispose()
    verb = "would delete" if args.dry_run else "deleted"
    for removal in removals:
        print(f"{verb} {removal.what} ({removal.size_bytes} bytes): {removal.reason}")
    total = sum(r.size_bytes for r in removals)
    print(f"{len(removals)} file(s), {total / 2**20:.1f} MiB {'to free' if args.dry_run else 'freed'}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "retention",
        help="delete old uploaded inputs, old sweep recordings and stale partial uploads",
        description="Delete the uploaded inputs of jobs that finished more than --retain-days ago, the "
        "recordings of sweeps that ended before then (never one a queued or running job needs; without "
        "--database, their copies stored in the data directory's database too, once they reached the "
        "central database) and partial uploads left by a crash; results stay in the database (`shockbench "
        "verify` still passes).",
    )
    add_database_arguments(p)
    p.add_argument(
        "--retain-days",
        type=float,
        default=DEFAULT_RETAIN_DAYS,
        help=f"keep what is younger than this (default {DEFAULT_RETAIN_DAYS:g})",
    )
    p.add_argument(
        "--lane", default=None, help="only this lane's jobs and sweeps (a database shared by lanes)"
    )
    p.add_argument("--dry-run", action="store_true", help="list what would be deleted, delete nothing")
    p.set_defaults(handler=run_retention_command)
