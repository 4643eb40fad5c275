"""`shockbench archive import FOLDER --database URL` and `archive export --database URL --out FOLDER`: a
folder of recordings into the database and back (service.reanalyse.archive). Exit code 0 when every file
went, 1 when some failed (each named in one line on stderr, the others done), 2 for bad input."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from service.cli.errors import EXIT_FAILED
from service.free_text import escaped


def _say(line: str) -> None:
    print(f"shockbench archive: {escaped(line)}", file=sys.stderr, flush=True)


def _other_vehicle(lines: list[str]) -> str:
    return f" ({len(lines)} of them given with another vehicle text: the stored one kept)" if lines else ""


def run_import(args: argparse.Namespace) -> int:
    from service.reanalyse.archive import import_folder
    from service.store.database import Database

    database = Database(args.database)
    try:
        database.upgrade_schema()  # a writer, as `serve` is: creates the tables in a new database
        report = import_folder(Path(args.folder), database, _say)
    finally:
        database.dispose()
    rate = report.stored / report.seconds if report.seconds > 0 else 0.0
    ratio = f", {report.bytes_stored / report.bytes_in:.0%} of their size" if report.bytes_in else ""
    print(
        f"stored {report.stored} recording(s) ({report.bytes_in / 1e6:.1f} MB{ratio}), "
        f"{report.already} stored before{_other_vehicle(report.other_vehicle)}, {len(report.failed)} failed; "
        f"{rate:.1f} recordings/s"
    )
    return EXIT_FAILED if report.failed else 0


def run_export(args: argparse.Namespace) -> int:
    from service.cli.db import open_database
    from service.reanalyse.archive import export_folder

    database = open_database(args.database, args.data)
    try:
        report = export_folder(database, Path(args.out), _say)
    finally:
        database.dispose()
    print(f"wrote {report.written} recording(s) to {args.out}, {len(report.failed)} failed")
    return EXIT_FAILED if report.failed else 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "archive",
        help="store a folder of recordings in the database, or write them back",
        description="A fleet's recordings in the central database, so that `reanalyse --database` needs "
        "no shared folder: `import` stores a folder's recordings (CSV or HDF5 with their vehicle files, as "
        "`reanalyse` finds them; idempotent by their sha256, a bad file fails alone), `export` writes them "
        "back with their vehicle files.",
    )
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    imp = actions.add_parser("import", help="store a folder's recordings in the database")
    imp.add_argument("folder", help="folder of recordings (searched recursively)")
    imp.add_argument("--database", required=True, metavar="URL", help="SQLAlchemy URL")
    imp.set_defaults(handler=run_import)
    exp = actions.add_parser("export", help="write the database's recordings to a folder")
    exp.add_argument("--database", default=None, metavar="URL", help="SQLAlchemy URL")
    exp.add_argument("--data", default="shockbench-data", help="data directory (default ./shockbench-data)")
    exp.add_argument("--out", required=True, help="folder to write them to")
    exp.set_defaults(handler=run_export)
