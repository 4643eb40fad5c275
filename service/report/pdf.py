"""The report as a PDF: A4 pages laid out top to bottom (title, then each section's paragraphs, tables and
plots, a block that does not fit starting the next page; a table may continue on it row by row), drawn
with matplotlib and written by its PDF backend (matplotlib.backends.backend_pdf.PdfPages): text as
TrueType text, plots as vectors, no creation date, so the same content gives the same bytes.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from functools import cache
from typing import Any

from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.lines import Line2D
from matplotlib.textpath import text_to_path

from service.report.content import Block, Paragraph, Plot, ReportContent, Section, Table
from service.report.plots import draw, rendering

PAGE_IN = (8.27, 11.69)
"""A4 portrait (inches)."""
MARGIN_IN = 0.6
BODY_PT = 8.5
LINE = 1.4
"""Line height in font sizes."""
ASCENT = 1.0
"""Baseline below a line box's top, in font sizes."""
OUTCOME_COLOURS = {"pass": "#1b7f3b", "check": "#b36b00", "fail": "#b3261e", "none": "0.3"}
PLOT_LEFT_IN = 0.6
"""Room left of a plot for its axis labels."""


def inches(points: float) -> float:
    return points / 72.0


@cache
def text_width_in(text: str, size_pt: float, weight: str = "normal") -> float:
    """How wide `text` is drawn (DejaVu Sans, matplotlib's own font)."""
    font = FontProperties(size=size_pt, weight=weight)
    return inches(text_to_path.get_text_width_height_descent(text, font, ismath=False)[0])


def wrap(text: str, width_in: float, size_pt: float = BODY_PT, weight: str = "normal") -> list[str]:
    """`text` in lines no wider than `width_in`, broken between words (inside a word longer than a line)."""
    lines: list[str] = []
    line = ""
    for word in text.split(" "):
        candidate = f"{line} {word}" if line else word
        if text_width_in(candidate, size_pt, weight) <= width_in:
            line = candidate
            continue
        if line:
            lines.append(line)
        line = word
        while text_width_in(line, size_pt, weight) > width_in and len(line) > 1:
            cut = len(line) - 1
            while cut > 1 and text_width_in(line[:cut], size_pt, weight) > width_in:
                cut -= 1
            lines.append(line[:cut])
            line = line[cut:]
    return [*lines, line]


@dataclass
class Sheet:
    """Pages being laid out; `y_in` is the cursor's distance from the top of the current page."""

    content: ReportContent
    pages: list[Figure] = field(default_factory=list)
    y_in: float = 0.0

    @property
    def page(self) -> Figure:
        return self.pages[-1]

    @property
    def width_in(self) -> float:
        return PAGE_IN[0] - 2 * MARGIN_IN

    def new_page(self) -> None:
        self.pages.append(Figure(figsize=PAGE_IN))
        self.y_in = MARGIN_IN

    def room(self, height_in: float) -> None:
        """Start a new page unless `height_in` fits above the bottom margin (and the footer)."""
        if self.y_in + height_in > PAGE_IN[1] - MARGIN_IN - 0.2:
            self.new_page()

    def text(self, x_in: float, text: str, size_pt: float = BODY_PT, **style: Any) -> None:
        """One line of `text` in a line box whose top is at the cursor, `x_in` from the left margin."""
        x = (MARGIN_IN + x_in) / PAGE_IN[0]
        baseline = self.y_in + inches(size_pt * ASCENT)
        self.page.text(x, 1 - baseline / PAGE_IN[1], text, fontsize=size_pt, va="baseline", **style)

    def lines(self, text: str, size_pt: float, **style: Any) -> None:
        """`text` wrapped to the page's width, the cursor below it."""
        for line in wrap(text, self.width_in, size_pt, style.get("weight", "normal")):
            self.room(inches(size_pt * LINE))
            self.text(0, line, size_pt, **style)
            self.y_in += inches(size_pt * LINE)

    def rule(self, weight: float = 0.4, colour: str = "0.75") -> None:
        y = 1 - self.y_in / PAGE_IN[1]
        x0, x1 = MARGIN_IN / PAGE_IN[0], 1 - MARGIN_IN / PAGE_IN[0]
        self.page.add_artist(
            Line2D([x0, x1], [y, y], lw=weight, color=colour, transform=self.page.transFigure)
        )

    def title(self) -> None:
        self.new_page()
        self.lines(self.content.title, 15, weight="bold")
        self.lines(self.content.subtitle, BODY_PT, color="0.35")

    def heading(self, title: str, first: Block | None) -> None:
        """The section's title, on the page where its first block starts (never alone at a page's end)."""
        if isinstance(first, Plot):
            after = first.height_in + 0.3
        elif isinstance(first, Table):
            after = 2 * inches(BODY_PT * LINE) + 0.1
        else:
            after = 0.35
        self.room(inches(11 * LINE) + 0.1 + after)
        self.y_in += 0.1
        self.text(0, title, 11, weight="bold")
        self.y_in += inches(11 * LINE)

    def paragraph(self, block: Paragraph) -> None:
        if block.style.startswith("outcome-"):
            self.lines(
                block.text, 14, weight="bold", color=OUTCOME_COLOURS[block.style.removeprefix("outcome-")]
            )
        elif block.style == "note":
            self.lines(block.text, 7.5, color="0.3")
        else:
            self.lines(block.text, BODY_PT, family="monospace" if block.style == "mono" else "sans-serif")
        self.y_in += 0.03

    def table(self, block: Table) -> None:
        weights = block.widths or (1.0,) * len(block.rows[0])
        widths = [self.width_in * w / sum(weights) for w in weights]
        starts = [sum(widths[:k]) for k in range(len(widths))]
        line = inches(BODY_PT * LINE)

        def row(cells: tuple[str, ...], header: bool = False) -> None:
            styles = []
            for k, cell in enumerate(cells):
                colour = OUTCOME_COLOURS.get(cell.lower())
                bold = header or colour is not None or (block.header is None and k % 2 == 0)
                styles.append({"weight": "bold" if bold else "normal", "color": colour or "black"})
            wrapped = [
                wrap(cell, width - 0.1, BODY_PT, style["weight"])
                for cell, width, style in zip(cells, widths, styles, strict=True)
            ]
            height = line * max(len(w) for w in wrapped) + 0.03
            self.room(height)
            top = self.y_in
            for x, lines, style in zip(starts, wrapped, styles, strict=True):
                for n, text in enumerate(lines):
                    self.y_in = top + n * line
                    self.text(x, text, BODY_PT, **style)
            self.y_in = top + height
            self.rule()

        if block.header is not None:
            row(block.header, header=True)
        for cells in block.rows:
            row(cells)
        self.y_in += 0.06

    def plot(self, block: Plot) -> None:
        caption = inches(7.5 * LINE)
        self.room(block.height_in + caption + 0.1)
        left = MARGIN_IN + PLOT_LEFT_IN
        width = self.width_in - PLOT_LEFT_IN - 0.05
        top = self.y_in + 0.05
        bottom = top + block.height_in - 0.5  # room below for the x axis' ticks and label
        rect = (left / PAGE_IN[0], 1 - bottom / PAGE_IN[1], width / PAGE_IN[0], (bottom - top) / PAGE_IN[1])
        draw(block, self.content, self.page, rect)
        self.y_in += block.height_in
        self.lines(block.caption, 7.5, color="0.3", style="italic")
        self.y_in += 0.06

    def section(self, section: Section) -> None:
        self.heading(section.title, section.blocks[0] if section.blocks else None)
        for block in section.blocks:
            if isinstance(block, Paragraph):
                self.paragraph(block)
            elif isinstance(block, Table):
                self.table(block)
            else:
                self.plot(block)

    def footers(self) -> None:
        for number, page in enumerate(self.pages, start=1):
            text = f"{self.content.footer} — page {number} of {len(self.pages)}"
            page.text(MARGIN_IN / PAGE_IN[0], 0.4 / PAGE_IN[1], text, fontsize=7, color="0.4")


def page_figures(content: ReportContent) -> list[Figure]:
    """The report's pages as matplotlib figures (call inside `rendering()`)."""
    sheet = Sheet(content)
    sheet.title()
    for section in content.sections:
        sheet.section(section)
    sheet.footers()
    return sheet.pages


def render_pdf(content: ReportContent) -> bytes:
    """The report as PDF bytes (deterministic: no creation date)."""
    buffer = io.BytesIO()
    metadata = {
        "Title": content.title,
        "Subject": content.subtitle,
        "Creator": "shockbench",
        "CreationDate": None,
    }
    with rendering(), PdfPages(buffer, metadata=metadata) as pdf:
        for page in page_figures(content):
            pdf.savefig(page)
    return buffer.getvalue()
