"""Page primitives of the report: an A4 figure, tables in an axes, and pages of text tables.

Figures are `matplotlib.figure.Figure` objects drawn on the Agg canvas (no pyplot state, so
reports can be made from any thread). `TextPages` lays out headings, paragraphs and tables
from the top of a page down, in figure coordinates, measuring the text with the Agg renderer:
columns get the width their content needs, text that does not fit its column (or the page) is
wrapped at spaces, a header never runs into its neighbour, and what does not fit on one page
continues on the next (matplotlib's `Axes.table` gives every row one line's height and never
wraps, so a title page of tables is laid out here instead).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import lru_cache
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.patches import Rectangle

A4_PORTRAIT_IN = (8.27, 11.69)
POINTS_PER_INCH = 72.0
CELL_PAD_PT = 6.0  # space between a column's text and the next column
LINE_SPACING = 1.35  # baseline-to-baseline distance, in font sizes
MIN_TABLE_SIZE_PT = 5.5  # a table is shrunk down to this size before its words are split


def new_figure() -> Figure:
    """An empty A4 portrait page on the Agg canvas."""
    fig = Figure(figsize=A4_PORTRAIT_IN)
    FigureCanvasAgg(fig)
    return fig


def plot_page(title: str, subtitle: str = "") -> Figure:
    """An A4 page for plots (constrained layout) with a bold title; the title is wrapped to the page."""
    fig = Figure(figsize=A4_PORTRAIT_IN, layout="constrained")
    FigureCanvasAgg(fig)
    width_pt = A4_PORTRAIT_IN[0] * POINTS_PER_INCH * 0.92
    lines = wrap_to_width(title, 12.0, width_pt, bold=True)
    if subtitle:
        lines += wrap_to_width(subtitle, 12.0, width_pt, bold=True)
    fig.suptitle("\n".join(lines), fontsize=12, fontweight="bold")
    return fig


def plain_log_ticks(ax: Any) -> None:
    """Label a logarithmic frequency axis in plain numbers (0.1, 1, 10, 100 kHz, not 10⁻¹, 10⁰,
    10¹), and, when it spans at most two decades, at 2 and 5 between them too (a 0.5–20 kHz axis
    would otherwise carry only "1" and "10")."""
    from matplotlib.ticker import FuncFormatter

    def major(x: float, _pos: int) -> str:
        return f"{x:g}"

    def minor(x: float, _pos: int) -> str:
        lo, hi = sorted(ax.get_xlim())
        if lo <= 0 or hi / lo > 10 ** 2.05:
            return ""
        mantissa = x / 10 ** math.floor(math.log10(x) + 1e-9)
        return f"{x:g}" if round(mantissa, 6) in (2.0, 5.0) else ""

    ax.xaxis.set_major_formatter(FuncFormatter(major))
    ax.xaxis.set_minor_formatter(FuncFormatter(minor))


# The width a full-width axes of a plot page keeps for a table (constrained layout leaves
# room for the other axes' y labels on the left): on the safe side of what it draws.
TABLE_WIDTH_PT = A4_PORTRAIT_IN[0] * POINTS_PER_INCH * 0.84

MEASURE_DPI = 720.0  # fine enough for the outline's own width
HINTING_MARGIN = 1.09  # hinted text in an 80–100 dpi PNG renders up to 8 % wider than its outline


@lru_cache(maxsize=8192)
def text_width_pt(text: str, size: float, bold: bool = False) -> float:
    """The width one line of `text` at `size` points (DejaVu Sans, matplotlib's default) may take
    on the page, points: its outline measured at MEASURE_DPI, with the HINTING_MARGIN a screen
    resolution PNG needs (the PDF draws the outline)."""
    renderer = _measuring_renderer()
    prop = FontProperties(size=size, weight="bold" if bold else "normal")
    width_px, _h, _d = renderer.get_text_width_height_descent(text, prop, ismath=False)
    return float(width_px) * POINTS_PER_INCH / renderer.dpi * HINTING_MARGIN


@lru_cache(maxsize=1)
def _measuring_renderer() -> Any:
    return FigureCanvasAgg(Figure(dpi=MEASURE_DPI)).get_renderer()


def wrap_to_width(text: str, size: float, width_pt: float, bold: bool = False) -> list[str]:
    """`text` broken at spaces (and at its own newlines) into lines no wider than `width_pt`;
    a single word wider than that is split where it must be."""
    out: list[str] = []
    for paragraph in str(text).split("\n"):
        words = paragraph.split(" ")
        line = ""
        for word in words:
            candidate = f"{line} {word}" if line else word
            if text_width_pt(candidate, size, bold) <= width_pt or not line:
                line = candidate
            else:
                out.append(line)
                line = word
            while text_width_pt(line, size, bold) > width_pt and len(line) > 1:
                cut = _longest_prefix(line, size, width_pt, bold)
                out.append(line[:cut])
                line = line[cut:]
        out.append(line)
    return out


def _longest_prefix(text: str, size: float, width_pt: float, bold: bool) -> int:
    lo, hi = 1, len(text)
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if text_width_pt(text[:mid], size, bold) <= width_pt:
            lo = mid
        else:
            hi = mid - 1
    return lo


def _min_width_pt(text: str, size: float, bold: bool) -> float:
    """The width of the widest word: a column is never narrower (its words would be split)."""
    return max((text_width_pt(w, size, bold) for line in str(text).split("\n") for w in line.split(" ")),
               default=0.0)


def _natural_width_pt(text: str, size: float, bold: bool) -> float:
    return max((text_width_pt(line, size, bold) for line in str(text).split("\n")), default=0.0)


def column_widths_pt(header: Sequence[str] | None, rows: Sequence[Sequence[str]], size: float,
                     available_pt: float) -> list[float] | None:
    """Widths that fit `available_pt`: each column its natural width (header and cells on one
    line) when they all fit, the spare width shared out; otherwise every column at least its
    widest word, the rest shared in proportion to what each column would like. None when even
    the widest words do not fit (shrink the text)."""
    cells = [list(header)] if header else []
    cells += [[str(c) for c in row] for row in rows]
    n = len(cells[0])
    pad = CELL_PAD_PT
    natural = [max(_natural_width_pt(r[i], size, bold=(header is not None and k == 0)) for k, r in enumerate(cells))
               + pad for i in range(n)]
    minimum = [max(_min_width_pt(r[i], size, bold=(header is not None and k == 0)) for k, r in enumerate(cells))
               + pad for i in range(n)]
    if sum(natural) <= available_pt:
        spare = (available_pt - sum(natural)) / n
        return [w + spare for w in natural]
    if sum(minimum) > available_pt:
        return None
    want = [nat - mn for nat, mn in zip(natural, minimum, strict=True)]
    share = (available_pt - sum(minimum)) / sum(want)
    return [mn + w * share for mn, w in zip(minimum, want, strict=True)]


class TextPages:
    """Headings, paragraphs and tables from the top of a page down; continues on a new page.

    `pages` holds every figure made; `start_page(fig)` is called on each new one (a title or a
    "continued" line). Positions are in points from the page's top-left corner.
    """

    def __init__(self, first: Figure, *, top_pt: float = 40.0, margin_pt: float = 42.0, bottom_pt: float = 40.0,
                 continued: Callable[[Figure], float] | None = None) -> None:
        self.pages = [first]
        self.fig = first
        self.width_pt = first.get_figwidth() * POINTS_PER_INCH
        self.height_pt = first.get_figheight() * POINTS_PER_INCH
        self.left = margin_pt
        self.right = self.width_pt - margin_pt
        self.bottom = self.height_pt - bottom_pt
        self.y = top_pt
        self._continued = continued

    # -- coordinates --------------------------------------------------------------------------
    def _fx(self, x_pt: float) -> float:
        return x_pt / self.width_pt

    def _fy(self, y_pt: float) -> float:
        return 1.0 - y_pt / self.height_pt

    def _room(self, height_pt: float) -> None:
        """Start a new page unless `height_pt` fits below the current position."""
        if self.y + height_pt <= self.bottom:
            return
        fig = new_figure()
        self.pages.append(fig)
        self.fig = fig
        self.y = self._continued(fig) if self._continued is not None else 40.0

    def text(self, x_pt: float, text: str, size: float, bold: bool = False, colour: str = "black",
             ha: str = "left") -> None:
        """One line at the current position (its top at self.y)."""
        self.fig.text(self._fx(x_pt), self._fy(self.y), text, fontsize=size, va="top", ha=ha,
                      fontweight="bold" if bold else "normal", color=colour, parse_math=False)

    # -- blocks -------------------------------------------------------------------------------
    def centred(self, text: str, size: float = 13.0, bold: bool = True) -> None:
        """Centred text (a title), wrapped to the page width."""
        self.lines(wrap_to_width(text, size, self.right - self.left, bold=bold), size, bold=bold, centred=True)

    def lines(self, lines: Sequence[str], size: float, bold: bool = False, centred: bool = False,
              colour: str = "black") -> None:
        step = LINE_SPACING * size
        for line in lines:
            self._room(step)
            x = (self.left + self.right) / 2 if centred else self.left
            self.text(x, line, size, bold, colour, ha="center" if centred else "left")
            self.y += step

    def heading(self, text: str, size: float = 10.5) -> None:
        self._room(4.0 * size)  # a heading is never the last line of a page
        self.y += 0.6 * size
        self.lines(wrap_to_width(text, size, self.right - self.left, bold=True), size, bold=True)
        self.y += 0.2 * size

    def paragraph(self, text: str, size: float = 8.0, colour: str = "black") -> None:
        self.lines(wrap_to_width(text, size, self.right - self.left), size, colour=colour)
        self.y += 0.4 * size

    def space(self, points: float) -> None:
        self.y += points

    def table(self, header: Sequence[str] | None, rows: Sequence[Sequence[str]], size: float = 8.0,
              widths: Sequence[float] | None = None) -> None:
        """A table; column widths from the content (or relative `widths`), text wrapped to them.

        A table too wide for the page at `size` is drawn smaller (down to MIN_TABLE_SIZE_PT)."""
        if not rows and not header:
            return
        available = self.right - self.left
        cols: list[float] | None
        while True:
            if widths is not None:
                total = float(sum(widths))
                cols = [available * w / total for w in widths]
            else:
                cols = column_widths_pt(header, rows, size, available)
            if cols is not None or size <= MIN_TABLE_SIZE_PT:
                break
            size = max(MIN_TABLE_SIZE_PT, size - 0.5)
        if cols is None:  # even the smallest text does not fit: equal columns, words split
            cols = [available / len(rows[0] if rows else header)] * len(rows[0] if rows else header)
        xs = [self.left + sum(cols[:i]) for i in range(len(cols))]
        step = LINE_SPACING * size

        def wrapped(row: Sequence[str], bold: bool) -> list[list[str]]:
            return [wrap_to_width(str(c), size, w - CELL_PAD_PT, bold) for c, w in zip(row, cols, strict=True)]

        def draw(cells: list[list[str]], shade: str | None, bold: bool) -> None:
            height = step * max(len(c) for c in cells) + 0.35 * size
            self._room(height)
            if shade is not None:
                self.fig.add_artist(Rectangle((self._fx(self.left), self._fy(self.y + height)),
                                              self._fx(available), height / self.height_pt,
                                              transform=self.fig.transFigure, color=shade, zorder=-1, lw=0))
            top = self.y
            for x, lines in zip(xs, cells, strict=True):
                self.y = top + 0.2 * size
                for line in lines:
                    self.text(x + 1.5, line, size, bold)
                    self.y += step
            self.y = top + height

        head_cells = wrapped(header, True) if header else None
        if head_cells is not None:
            draw(head_cells, "0.88", True)
        for n, row in enumerate(rows):
            if head_cells is not None and self.y + step * 2 > self.bottom:
                self._room(self.height_pt)  # a new page: repeat the header
                draw(head_cells, "0.88", True)
            draw(wrapped(row, False), "0.955" if n % 2 else None, False)
        self.y += 0.6 * step


def table_in_axes(ax: Any, header: list[str] | None, rows: list[list[str]], fontsize: float = 8.0,
                  col_widths: list[float] | None = None, line_heights: bool = False,
                  width_pt: float | None = None) -> None:
    """A small table at the top of an axes (matplotlib's table). Every row is one line high,
    unless `line_heights`: then a row is as high as its cells' lines. With `width_pt` (the
    axes' width on the page, points) and `col_widths`, each cell is first wrapped to its
    column's measured width (`wrap_cells`), so no text runs under its neighbour."""
    ax.axis("off")
    if not rows:
        ax.text(0.0, 1.0, "—", va="top", transform=ax.transAxes)
        return
    if width_pt is not None and col_widths is not None:
        header = wrap_cells([header], col_widths, width_pt, fontsize, bold=True)[0] if header else header
        rows = wrap_cells(rows, col_widths, width_pt, fontsize)
        line_heights = True
    t = ax.table(cellText=rows, colLabels=header, loc="upper center", cellLoc="left", colLoc="left",
                 colWidths=col_widths)
    t.auto_set_font_size(False)
    t.set_fontsize(fontsize)
    t.scale(1.0, 1.25)
    if line_heights:
        table_rows = ([header] if header is not None else []) + rows
        for (r, _c), cell in t.get_celld().items():
            lines = max(str(c).count("\n") + 1 for c in table_rows[r])
            cell.set_height(cell.get_height() * lines)
    for (r, _c), cell in t.get_celld().items():
        cell.set_edgecolor("0.75")
        if header is not None and r == 0:
            cell.set_facecolor("0.9")
            cell.set_text_props(fontweight="bold")


TABLE_CELL_PAD = 0.1  # matplotlib's Cell.PAD: a cell's text is inset by this fraction of the cell's width on each side


def wrap_cells(rows: Sequence[Sequence[str]], col_widths: Sequence[float], width_pt: float, fontsize: float,
               bold: bool = False) -> list[list[str]]:
    """Each cell wrapped at spaces (`wrap_to_width`) to what its column of `table_in_axes` leaves
    for text: the column's share of `width_pt` less matplotlib's padding on both sides."""
    total = float(sum(col_widths))
    room = [width_pt * w / total * (1.0 - 2 * TABLE_CELL_PAD) for w in col_widths]
    return [["\n".join(wrap_to_width(str(c), fontsize, r, bold)) for c, r in zip(row, room, strict=True)]
            for row in rows]


def freeze_layout(fig: Figure) -> None:
    """Run the constrained layout once and keep it: every later save (PDF page, PNG) then
    draws the figure once instead of laying it out again (about half the time per save)."""
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
        fig.set_layout_engine("none")
