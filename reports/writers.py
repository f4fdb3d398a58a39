"""Writers of a report: PDF (one page per figure, through `PdfPages`) and HTML (PNG images
embedded as base64, every table as text). Each file is written atomically through
`hopkinson.fileio` (a temporary beside it, fsynced, renamed): a report is whole or absent.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Iterable, Sequence
from pathlib import Path

from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from hopkinson.analysis.errors import AnalysisError
from hopkinson.fileio import UnsafeOutputError, atomic_write, check_output_path
from hopkinson.reports.data import CalibrationReport
from hopkinson.reports.pages import SINE_CAPTION, report_pages
from hopkinson.reports.statistics import COMBINATION_NOTE, CampaignStatistics, campaign_statistics
from hopkinson.reports.tables import (
    BUDGET_NOTE,
    budget_rows,
    combined_rows,
    compensation_rows,
    dcm_rows,
    fmt,
    per_shot_rows,
    pole_rows,
    results_rows,
    sine_rows,
    spread_rows,
    uncertainty_method,
    uncertainty_rows,
)

PNG_DPI = 90
FORMATS = ("pdf", "html")


def _write_pdf(path: Path, report: CalibrationReport, pages: list[tuple[str, Figure]]) -> None:
    # Rendered in memory, then written with plain writes: matplotlib's PDF writer meeting a full
    # disk fails inside zlib ("buffer error"); this way a full disk is one OSError naming the file.
    buffer = io.BytesIO()
    with PdfPages(buffer, metadata={"Title": report.title, "Subject": "Hopkinson-bar shock calibration report",
                                    "Keywords": " ".join(e.label for e in report.shots),
                                    "Creator": "hopkinson"}) as pdf:
        for _caption, fig in pages:
            pdf.savefig(fig)
    atomic_write(path, buffer.getbuffer())


def _png(fig: Figure, dpi: int = PNG_DPI) -> bytes:
    """The figure as PNG bytes, rendered in memory (written with plain writes by the caller)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def _png_base64(fig: Figure) -> str:
    return base64.b64encode(_png(fig)).decode("ascii")


def html_table(header: list[str] | None, rows: Iterable[Sequence[str]], cls: str = "") -> str:
    """A table as HTML text (cells escaped); cls "kv" shows the first column bold."""
    out = [f'<table class="{cls}">' if cls else "<table>"]
    if header:
        out.append("<thead><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr></thead>")
    out.append("<tbody>")
    for row in rows:
        out.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


HTML_CSS = """
body { font-family: DejaVu Sans, Arial, sans-serif; margin: 2em auto; max-width: 60em; color: #222; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; margin-top: 2em; } h3 { margin-top: 1.5em; }
table { border-collapse: collapse; margin: 0.5em 0 1em 0; font-size: 0.9em; }
td, th { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; vertical-align: top; }
th { background: #eee; } table.kv td:first-child { font-weight: bold; white-space: nowrap; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; } .error { color: #a00; } .note { font-size: 0.85em; color: #444; }
"""


def _write_html(path: Path, report: CalibrationReport, pages: list[tuple[str, Figure]],
                stats: CampaignStatistics | None) -> None:
    e = html.escape
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{e(report.title)}</title>"
             f"<style>{HTML_CSS}</style></head><body>", f"<h1>{e(report.title)}</h1>",
             "<p>Hopkinson-bar shock calibration: dynamic model, band of small distortion (FBSD, ±5 % and ±10 %) "
             "and dynamic compensation model (DCM).</p>",
             "<h2>Accelerometer and rig</h2>", html_table(None, report.identity.items(), "kv")]
    by_caption = dict(pages)
    if report.campaign and stats is not None:
        parts.append("<h2>Shots</h2>")
        parts.append(html_table(*per_shot_rows(report.shots)))
        parts.append(f"<h2>Spread across {len(stats.labels)} analysed shots</h2>")
        parts.append(html_table(*spread_rows(stats)))
        header, rows = combined_rows(stats)
        if rows:
            parts.append("<h2>Key figures of the campaign</h2>" + html_table(header, rows)
                         + f"<p class='note'>{e(COMBINATION_NOTE)}</p>")
        if stats.sine:
            parts.append("<h2>Against the sinusoidal calibration</h2>" + html_table(*sine_rows(stats.sine)))
        for note in stats.sine_notes:
            parts.append(f"<p class='error'>{e(note)}</p>")
        parts.append("<h2>Cross-validation</h2><p>Row i: the model identified on shot i; column j: its response "
                     "simulated on shot j's reference, compared with shot j's measured response: fit % = "
                     "100·(1 − ‖y − ŷ‖/‖y − ȳ‖).</p>")
        m = stats.cross_validation_percent
        rows = [[stats.labels[i]] + [fmt(v, digits=5) for v in m[i]] for i in range(len(stats.labels))]
        parts.append(html_table(["model \\ shot"] + stats.labels, rows, "cv"))
        for caption in ("Campaign: cross-validation and spread", "Campaign: responses of all shots", SINE_CAPTION):
            if caption in by_caption:
                parts.append(_html_figure(caption, by_caption[caption]))
    for entry in report.shots:
        parts.append(f"<h2 id='shot-{e(entry.label)}'>Shot {e(entry.label)}</h2>")
        parts.append(html_table(None, list(entry.identity.items()) + [("state", entry.state or "—")], "kv"))
        if entry.analysis is None:
            parts.append(f"<p class='error'>No analysis: {e(entry.error or 'none stored')}</p>")
            continue
        parts.append("<h3>Results</h3>" + html_table(None, results_rows(entry), "kv"))
        check = entry.compensation
        if check is not None and check.recommended is False:
            parts.append(f"<p class='error'><b>DCM not recommended</b>: "
                         f"{e(check.not_recommended_reason or 'compensation does not improve this shot')}</p>")
        header, rows = uncertainty_rows(entry)
        if rows:
            parts.append("<h3>Measurement uncertainty</h3>" + html_table(header, rows)
                         + f"<p class='note'>{e(uncertainty_method(entry))}</p>")
            header, rows = budget_rows(entry)
            if rows:
                parts.append("<h4>Uncertainty budget: relative standard uncertainty (%)</h4>" + html_table(header, rows)
                             + f"<p class='note'>{e(BUDGET_NOTE)}</p>")
        rows = compensation_rows(entry)
        if rows:
            parts.append("<h3>Compensation checked on the shot itself</h3>" + html_table(None, rows, "kv"))
        for caption, fig in [(c, f) for c, f in pages if c.startswith(f"{entry.label}: ")]:
            parts.append(_html_figure(caption, fig))
            if caption.endswith("poles and zeros"):
                parts.append("<h3>Pole analysis (Table 1)</h3>" + html_table(*pole_rows(entry.analysis)))
            if caption.endswith("dynamic compensation model"):
                parts.append("<h3>DCM</h3>" + html_table(None, dcm_rows(entry.analysis), "kv"))
    if report.notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{e(n)}</li>" for n in report.notes) + "</ul>")
    parts.append("</body></html>\n")
    text = "\n".join(parts)
    atomic_write(path, text)


def _html_figure(caption: str, fig: Figure) -> str:
    return (f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,{_png_base64(fig)}'>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def write_report(report: CalibrationReport, paths: Sequence[str | Path], inputs: Sequence[str | Path] = (),
                 pages: list[tuple[str, Figure]] | None = None, stats: CampaignStatistics | None = None) -> list[Path]:
    """Write the report to each path; the format comes from the suffix (.pdf or .html).

    The pages are drawn once for all formats. Each file is written atomically (module doc).
    AnalysisError for an unknown suffix, a missing folder, an output that is one of `inputs`
    or an existing shot file, or a report without shots (checked before anything is drawn).
    `pages`, `stats`: the report's pages (`report_pages`) and campaign statistics when already
    made, else they are made here.
    """
    targets = [Path(p) for p in paths]
    for p in targets:
        if p.suffix.lower().lstrip(".") not in FORMATS:
            raise AnalysisError(f"{p}: a report is .pdf or .html")
        try:
            check_output_path(p, inputs, what="report")
        except UnsafeOutputError as exc:
            raise AnalysisError(str(exc)) from None
    if not report.shots:
        raise AnalysisError(f"report {report.title!r}: no shots to report")
    if stats is None and report.campaign:
        stats = campaign_statistics(report.shots, report.sine_calibration)
    if pages is None:
        pages = report_pages(report, stats)
    for p in targets:
        if p.suffix.lower() == ".pdf":
            _write_pdf(p, report, pages)
        else:
            _write_html(p, report, pages, stats)
    return targets


def write_pngs(pages: list[tuple[str, Figure]], folder: str | Path, prefix: str, dpi: int = PNG_DPI) -> list[Path]:
    """Each page as `<folder>/<prefix>-<nn>-<caption>.png` (for people to look at); the paths."""
    out = []
    for n, (caption, fig) in enumerate(pages, start=1):
        slug = "".join(c if c.isalnum() else "-" for c in caption.lower()).strip("-")
        slug = "-".join(part for part in slug.split("-") if part)[:60]
        path = Path(folder) / f"{prefix}-{n:02d}-{slug}.png"
        atomic_write(path, _png(fig, dpi))
        out.append(path)
    return out
