"""`shockbench report`: the sheet of a test, PDF or HTML, from an identification's result JSON.

    shockbench report RESULT.json --out REPORT.pdf                  # the figures, the verdict, the curve
    shockbench report RESULT.json --recording SWEEP.h5 --out R.html # and the sweep over time and frequency

RESULT.json is what `shockbench identify --json` prints, or the job the service answers
(`GET /api/v1/jobs/{id}`, the operator page's "Result JSON"). The recording (HDF5 sweep or recording CSV,
read as `identify` reads it) adds the plots over time and frequency and names the bench, operator and
start time. What neither file records (a vehicle id, the tyre pressure) the sheet says is not recorded:
the service's own report (`GET /api/v1/sweeps/{id}/report.pdf`) has them from the sweep.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from service.cli.errors import CliError
from service.cli.recording_input import RECORDING_HELP

FORMATS = (".pdf", ".html")
"""service.report.FORMATS, named here so that `shockbench --help` does not import the report's plots."""


def run_report(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() not in FORMATS:
        raise CliError(f"--out {out}: give a .pdf or an .html file name", field="out")
    if not out.parent.is_dir():
        raise CliError(f"--out {out}: no folder {out.parent}", field="out")
    from service.cli.recording_input import load_recording
    from service.report import write_report
    from service.report.source import read_result_file, with_recording
    from service.version import shockbench_version

    source = read_result_file(args.result, shockbench_version())
    if args.recording is not None:
        source = with_recording(source, load_recording("report", args.recording).recording, args.recording)
    write_report(source, out)
    print(f"wrote {out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="the sheet of a test (PDF or HTML) from an identification's result JSON",
        description="Write the test's report: vehicle and test record, verdict per corner with its "
        "thresholds, lane figures, damper curve with its 95% band, masses and stiffnesses with their "
        "intervals; with --recording also the sweep over time and the transmissibility.",
    )
    p.add_argument(
        "result", metavar="RESULT.json", help="`identify --json` output, or a job from GET /api/v1/jobs/{id}"
    )
    p.add_argument("--recording", default=None, metavar="REC", help=RECORDING_HELP + " (optional)")
    p.add_argument(
        "--out", required=True, metavar="FILE.pdf|FILE.html", help="report to write (.pdf or .html)"
    )
    p.set_defaults(handler=run_report)
