"""The report as one self-contained HTML page: its style inline in one <style> element, its plots SVG
images inside the page as data: URIs, no script, no link and no request to anywhere (it opens and prints
the same on a lane without a network). Every text is escaped.

`policy(page)` is the Content-Security-Policy the service sends it with: nothing may load but data:
images and the page's own style (by its hash), so even a browser never fetches anything for it.
"""

from __future__ import annotations

import base64
import hashlib
import io
from html import escape

from service.report.content import Paragraph, Plot, ReportContent, Section, Table
from service.report.plots import plot_figure, rendering

WIDTH_IN = 7.0
"""The plots' width: the page's printable width on A4."""

STYLE = """
@page { size: A4; margin: 14mm; }
body { font-family: "DejaVu Sans", Arial, Helvetica, sans-serif; font-size: 10pt; color: #111;
       max-width: 190mm; margin: 1em auto; padding: 0 1em; }
h1 { font-size: 17pt; margin: 0 0 0.1em; }
h2 { font-size: 12.5pt; margin: 1.2em 0 0.4em; border-bottom: 1px solid #999; }
p { margin: 0.3em 0; }
.subtitle, .note, figcaption, footer { color: #555; font-size: 8.5pt; }
.outcome-pass, .outcome-check, .outcome-fail, .outcome-none { font-size: 15pt; font-weight: bold; }
.outcome-pass { color: #1b7f3b; } .outcome-check { color: #b36b00; } .outcome-fail { color: #b3261e; }
.outcome-none { color: #555; }
.cell-pass, .cell-check, .cell-fail { font-weight: bold; }
.cell-pass { color: #1b7f3b; } .cell-check { color: #b36b00; } .cell-fail { color: #b3261e; }
.mono { font-family: "DejaVu Sans Mono", monospace; }
table { border-collapse: collapse; width: 100%; margin: 0.3em 0 0.6em; }
th, td { text-align: left; vertical-align: top; padding: 2px 6px; border-bottom: 1px solid #ccc; }
td { overflow-wrap: break-word; }
td:first-child { white-space: nowrap; }
figure { margin: 0.5em 0; page-break-inside: avoid; break-inside: avoid; }
figure img { width: 100%; height: auto; }
section { page-break-inside: auto; }
footer { margin-top: 2em; border-top: 1px solid #999; padding-top: 0.3em; }
""".strip()


def policy() -> str:
    """The page's Content-Security-Policy: its one style element by hash, data: images, nothing else."""
    digest = base64.b64encode(hashlib.sha256(STYLE.encode()).digest()).decode()
    return "; ".join(
        [
            "default-src 'none'",
            f"style-src 'sha256-{digest}'",
            "img-src data:",
            "base-uri 'none'",
            "form-action 'none'",
            "frame-ancestors 'none'",
        ]
    )


def svg_data_uri(plot: Plot, content: ReportContent) -> str:
    """The plot as an SVG image in a data: URI (call inside `rendering()`)."""
    fig = plot_figure(plot, content, WIDTH_IN)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="svg", metadata={"Date": None})
    return "data:image/svg+xml;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def _cell(text: str) -> str:
    """A table cell; a verdict (PASS, CHECK, FAIL) in its colour."""
    if text.lower() in ("pass", "check", "fail"):
        return f'<td class="cell-{text.lower()}">{escape(text)}</td>'
    return f"<td>{escape(text)}</td>"


def _table(block: Table) -> str:
    head = ""
    if block.header is not None:
        head = "<thead><tr>" + "".join(f"<th>{escape(c)}</th>" for c in block.header) + "</tr></thead>"
    if block.header is None:  # a record: label, value, label, value ...
        rows = [
            "<tr>"
            + "".join(
                f'<th scope="row">{escape(c)}</th>' if k % 2 == 0 else f"<td>{escape(c)}</td>"
                for k, c in enumerate(r)
            )
            + "</tr>"
            for r in block.rows
        ]
    else:
        rows = ["<tr>" + "".join(_cell(c) for c in r) + "</tr>" for r in block.rows]
    return f"<table>{head}<tbody>{''.join(rows)}</tbody></table>"


def _section(section: Section, content: ReportContent) -> str:
    parts = [f"<section><h2>{escape(section.title)}</h2>"]
    for block in section.blocks:
        if isinstance(block, Paragraph):
            style = f' class="{block.style}"' if block.style else ""
            parts.append(f"<p{style}>{escape(block.text)}</p>")
        elif isinstance(block, Table):
            parts.append(_table(block))
        else:
            source = svg_data_uri(block, content)
            caption = escape(block.caption)
            parts.append(
                f'<figure><img src="{source}" alt="{caption}"><figcaption>{caption}</figcaption></figure>'
            )
    parts.append("</section>")
    return "\n".join(parts)


def render_html(content: ReportContent) -> str:
    """The report as one HTML document (deterministic: the same content gives the same text)."""
    with rendering():
        sections = [_section(section, content) for section in content.sections]
    return "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en">',
            "<head>",
            '<meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            f"<title>{escape(content.title)}</title>",
            f"<style>{STYLE}</style>",
            "</head>",
            "<body>",
            f"<header><h1>{escape(content.title)}</h1>",
            f'<p class="subtitle">{escape(content.subtitle)}</p></header>',
            *sections,
            f"<footer>{escape(content.footer)}</footer>",
            "</body>",
            "</html>",
            "",
        ]
    )
