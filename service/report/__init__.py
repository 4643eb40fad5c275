"""A report per test, the sheet the customer takes home: HTML and PDF from a stored identification result.

What it shows (service.report.content): the vehicle id, operator, lane, bench, date and tyre pressure; the
verdict per corner with the thresholds that judged it (their version and limits); EUSAMA, the least phase
angle and the damping ratio per corner, with the left/right imbalance on an axle; the damper curve with
its 95% band (left and right overlaid on an axle); the sweep over time (plate, wheel, body) and the
transmissibility over frequency when the recording is at hand; the masses and stiffnesses with their 95%
intervals (and a lab rig's frame guides' friction); the model doctor's summary when it was run; and the
result's hash-chain record (lane and sequence), so that a printed sheet can be traced to the stored
result. A field the test did not record says "not recorded".

Rendering: `report_html` (service.report.html: one self-contained page, style inline, plots as SVG data:
URIs, no script and no external request) and `report_pdf` (service.report.pdf). The PDF is drawn with
matplotlib's own PDF backend (PdfPages), chosen over reportlab and WeasyPrint because:
- it is already a dependency (the curve plots): no new package, and no system library (WeasyPrint needs
  Pango and cairo, which a bench PC's minimal install may lack);
- the plots are the same matplotlib drawings in both formats, vector in the PDF, with no image round trip;
- it needs no network and no font outside matplotlib's own (DejaVu), embedded as TrueType, so the text
  reads back and searches;
- it is deterministic: no creation date is written, so the same result gives the same bytes.
Its cost is a small layout engine of our own (service.report.pdf: text, tables and plots top to bottom).

Where the input comes from (service.report.source): the service's database for
`GET /api/v1/sweeps/{id}/report.pdf` and `.html`, or a result JSON file for `shockbench report`.


Must not import service.cli nor simulators: the report is made from a stored result, by the API and
the command alike."""

from __future__ import annotations

from pathlib import Path

from daq.formats.atomic import atomic_write
from estimator.errors import UserError
from service.report.content import RecordedTest, ReportContent, ReportInput, ReportInputError, build_report
from service.report.html import policy, render_html
from service.report.pdf import render_pdf

__all__ = [
    "FORMATS",
    "RecordedTest",
    "ReportContent",
    "ReportInput",
    "ReportInputError",
    "build_report",
    "policy",
    "report_html",
    "report_pdf",
    "write_report",
]

FORMATS = (".pdf", ".html")


def report_pdf(source: ReportInput) -> bytes:
    """The report of `source` as a PDF (ReportInputError when its result is not an identification's)."""
    return render_pdf(build_report(source))


def report_html(source: ReportInput) -> str:
    """The report of `source` as one self-contained HTML page."""
    return render_html(build_report(source))


def write_report(source: ReportInput, out: Path | str) -> Path:
    """Write the report to `out`, PDF or HTML by its suffix, atomically (a reader never sees half)."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in FORMATS:
        raise UserError(f"{out}: a report is .pdf or .html, not {out.suffix or 'a name without a suffix'}")
    if suffix == ".pdf":
        with atomic_write(out, "wb") as handle:
            handle.write(report_pdf(source))
    else:
        with atomic_write(out, "wb") as handle:
            handle.write(report_html(source).encode("utf-8"))
    return out
