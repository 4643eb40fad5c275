"""`shockbench reanalyse`: identify (and diagnose) every recording of an archive on dask.distributed, and
compare two stored runs (`--compare`); the logic in service.reanalyse.
Exit code 0 when every recording succeeded, 1 when some failed (their reasons
are in the summary), 2 for bad input (no such folder, bad option, a scheduler that does not answer)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from estimator.vehicle import TyreModel
from service.cli.errors import EXIT_FAILED, CliError

DEFAULT_WORKERS = 2


def run_reanalyse(args: argparse.Namespace) -> int:
    from estimator.identify import check_curve_points
    from service.extras import require_extra
    from service.reanalyse.progress import RunProgress
    from service.reanalyse.run import DASK_NEEDED_FOR, RunSettings, dashboard_link, reanalyse
    from service.reanalyse.sources import items_in_database, items_in_folder, open_archive
    from service.reanalyse.task import Analysis, AnalysisOptions

    if args.compare is not None:
        return run_compare(args)
    require_extra("cluster", DASK_NEEDED_FOR)  # before any work: not after scanning an archive
    if (args.source is None) == (args.database is None):
        raise CliError("give either SOURCE (a folder of recordings) or --database URL, not both")
    if args.source is not None and args.out is None:
        raise CliError("--out is needed with SOURCE (the results go there)")
    if args.workers < 1:
        raise CliError(f"--workers must be at least 1, got {args.workers}")
    if args.batch is not None and args.batch < 1:
        raise CliError(f"--batch must be at least 1, got {args.batch}")
    check_curve_points(args.points, "--points")
    out = Path(args.out) if args.out is not None else None
    if out is not None and out.exists() and not out.is_dir():
        raise CliError(f"--out {out}: exists and is not a folder")
    database = open_archive(args.database) if args.database else None
    try:
        items = (
            items_in_database(database) if database is not None else items_in_folder(Path(args.source), out)
        )
        settings = RunSettings(
            out=out,
            analyses=(Analysis.IDENTIFY, Analysis.DIAGNOSE) if args.diagnose else (Analysis.IDENTIFY,),
            options=AnalysisOptions(tyre=args.tyre, points=args.points),
            scheduler=args.scheduler,
            workers=args.workers,
            database=database,
            batch=args.batch,
        )
        progress = RunProgress(sys.stderr)
        try:
            # lines name recordings: file names, or text stored in the database (RunProgress escapes them)
            report = reanalyse(
                items,
                settings,
                progress.say,
                progress,
                lambda client: progress.dashboard(dashboard_link(client)),
            )
        finally:
            progress.close()
    finally:
        if database is not None:
            database.dispose()
    total = len(report.rows)
    where = [str(report.summary)] if report.summary is not None else []
    if report.run_id is not None:
        where.append(f"run {report.run_id} in {database.safe_url if database else ''}")
    print(f"results: {', '.join(where)} ({total - report.failed} ok, {report.failed} failed)")
    if report.failed:
        print(
            f"shockbench reanalyse: {report.failed} of {total} recording(s) failed; reasons in {where[0]}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    return 0


def run_compare(args: argparse.Namespace) -> int:
    """`--compare A B`: how far the results of B moved from A's (service.reanalyse.compare)."""
    from service.reanalyse.compare import compare_runs, plot_changes, render
    from service.reanalyse.sources import open_archive

    if args.database is None:
        raise CliError("--compare needs --database URL (the runs are stored there)")
    database = open_archive(args.database)
    try:
        comparison = compare_runs(database, *args.compare)
    finally:
        database.dispose()
    print(render(comparison, top=args.top))
    if args.plot is not None:
        plot_changes(comparison, Path(args.plot))
        print(f"plot: {args.plot}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reanalyse",
        help="identify (and diagnose) every recording of an archive on dask.distributed",
        description="Re-analyse an archive: identify every recording of a folder (CSV or HDF5, each with "
        "its vehicle file: REC.vehicle.toml, REC.toml, vehicle.toml in its folder, or the vehicle text an "
        "HDF5 sweep carries) or every recording stored in a database (`shockbench archive import`, and the "
        "sweeps' own), on a local Dask cluster or a running scheduler. Writes OUT/<name>.identify.json (and "
        ".diagnose.json) as each finishes and OUT/summary.csv (a re-run skips what is done on unchanged "
        "input); with --database, the results are stored there as a run, which --compare compares with "
        "another run or the original results. A bad recording fails alone.",
    )
    p.add_argument("source", nargs="?", default=None, help="folder of recordings (searched recursively)")
    p.add_argument(
        "--database", default=None, metavar="URL", help="every recording stored here, instead of SOURCE"
    )
    p.add_argument(
        "--out",
        default=None,
        help="folder for the result files and summary.csv (needed with SOURCE; with --database the run is "
        "stored there too)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="tcp://HOST:PORT",
        help="a running Dask scheduler (the recordings' bytes are sent to its workers: no shared folder); "
        "default: a local cluster",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=DEFAULT_WORKERS,
        help=f"worker processes of the local cluster, one thread each (default {DEFAULT_WORKERS})",
    )
    p.add_argument(
        "--batch",
        type=int,
        default=None,
        help="recordings per Dask task (default: up to 8, fewer towards the end)",
    )
    p.add_argument("--diagnose", action="store_true", help="run the model doctor on each recording too")
    p.add_argument("--tyre", choices=[t.value for t in TyreModel], default="maxwell")
    p.add_argument("--points", type=int, default=None, help="curve points (each command's default)")
    p.add_argument(
        "--compare",
        nargs=2,
        default=None,
        metavar=("RUN_A", "RUN_B"),
        help="with --database: how far run B's results moved from run A's ('original': the lanes' stored "
        "results), per vehicle and over the fleet, largest first; nothing is run",
    )
    p.add_argument(
        "--top", type=int, default=20, help="with --compare: the largest changes listed (default 20)"
    )
    p.add_argument("--plot", default=None, metavar="PNG", help="with --compare: the distribution of changes")
    p.set_defaults(handler=run_reanalyse)
