"""`shockbench reanalyse`: identify (and diagnose) every recording of an archive on dask.distributed, the
logic in service.reanalyse. Exit code 0 when every recording succeeded, 1 when some failed (their reasons
are in the summary), 2 for bad input (no such folder, bad option, a scheduler that does not answer)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from estimator.vehicle import TyreModel
from service.cli.errors import EXIT_FAILED, CliError
from service.free_text import escaped

DEFAULT_WORKERS = 2


def run_reanalyse(args: argparse.Namespace) -> int:
    from estimator.identify import check_curve_points
    from service.extras import require_extra
    from service.reanalyse.run import DASK_NEEDED_FOR, RunSettings, reanalyse
    from service.reanalyse.sources import items_in_database, items_in_folder
    from service.reanalyse.task import Analysis, AnalysisOptions

    require_extra("cluster", DASK_NEEDED_FOR)  # before any work: not after scanning an archive
    if (args.source is None) == (args.database is None):
        raise CliError("give either SOURCE (a folder of recordings) or --database URL, not both")
    if args.workers < 1:
        raise CliError(f"--workers must be at least 1, got {args.workers}")
    check_curve_points(args.points, "--points")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {out}: exists and is not a folder")
    items = items_in_database(args.database) if args.database else items_in_folder(Path(args.source), out)
    settings = RunSettings(
        out=out,
        analyses=(Analysis.IDENTIFY, Analysis.DIAGNOSE) if args.diagnose else (Analysis.IDENTIFY,),
        options=AnalysisOptions(tyre=args.tyre, points=args.points),
        scheduler=args.scheduler,
        workers=args.workers,
    )
    # a line names a recording and why it failed: a file name, or text stored in the database (escaped)
    report = reanalyse(items, settings, lambda line: print(escaped(line), file=sys.stderr, flush=True))
    total = len(report.rows)
    print(f"summary: {report.summary} ({total - report.failed} ok, {report.failed} failed)")
    if report.failed:
        print(
            f"shockbench reanalyse: {report.failed} of {total} recording(s) failed; "
            f"reasons in {report.summary}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reanalyse",
        help="identify (and diagnose) every recording of an archive on dask.distributed",
        description="Re-analyse an archive: identify every recording of a folder (CSV or HDF5, each with "
        "its vehicle file: REC.vehicle.toml, REC.toml, vehicle.toml in its folder, or the vehicle text an "
        "HDF5 sweep carries) or every complete sweep of a database, on a local Dask cluster or a running "
        "scheduler. Writes OUT/<name>.identify.json (and .diagnose.json) as each finishes and "
        "OUT/summary.csv; a re-run skips what is done on unchanged input. A bad recording fails alone.",
    )
    p.add_argument("source", nargs="?", default=None, help="folder of recordings (searched recursively)")
    p.add_argument(
        "--database", default=None, metavar="URL", help="every complete sweep stored here, instead of SOURCE"
    )
    p.add_argument("--out", required=True, help="folder for the result files and summary.csv")
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="tcp://HOST:PORT",
        help="a running Dask scheduler (its workers must see the recordings at the same paths); "
        "default: a local cluster",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=DEFAULT_WORKERS,
        help=f"worker processes of the local cluster, one thread each (default {DEFAULT_WORKERS})",
    )
    p.add_argument("--diagnose", action="store_true", help="run the model doctor on each recording too")
    p.add_argument("--tyre", choices=[t.value for t in TyreModel], default="maxwell")
    p.add_argument("--points", type=int, default=None, help="curve points (each command's default)")
    p.set_defaults(handler=run_reanalyse)
