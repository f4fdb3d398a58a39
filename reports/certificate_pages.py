"""A calibration certificate drawn from its stored content (hopkinson.lab.certificate): PDF
pages (matplotlib, reports.layout.TextPages) and an HTML page, both in the same order of
sections (`sections`), each page numbered "page n of N" and the last ending with "End of
certificate". Both are rendered to bytes first; the caller writes them.

Text the PDF's fonts cannot draw (CJK, emoji) is never printed as empty boxes: matplotlib
falls back through `FALLBACK_FONTS` (whichever are installed), and a character none of them
has is refused with the characters named (`UndrawableText`), so no number is issued for a
document that could not say what it must.
"""

from __future__ import annotations

import html
import io
from functools import lru_cache
from typing import Any

PRIMARY_FONT = "DejaVu Sans"
FALLBACK_FONTS = ("Noto Sans CJK JP", "Noto Sans CJK SC", "Noto Sans CJK TC", "Noto Sans CJK KR",
                  "WenQuanYi Micro Hei", "WenQuanYi Zen Hei", "Droid Sans Fallback", "Noto Emoji", "Symbola")


class UndrawableText(ValueError):
    """Characters no installed font can draw (the message names them and what to install)."""


def sections(content: dict[str, Any]) -> list[tuple[str, str, Any]]:
    """(heading, kind, data) in the certificate's order: kind "kv", "table", "text", "note" or "list"."""
    stated = content["stated"]
    return [
        ("", "kv", _heading_rows(content)),
        ("Job", "kv", content["job"]),
        ("Item calibrated", "kv", content["item"]),
        ("Method", "text", f"{content['method']} Software: hopkinson {content['software_version']}"
                           + (f" (analysis: {', '.join(content['analysis_software'])})"
                              if content.get("analysis_software") else "") + "."),
        ("Deviations from the method", "list", content["deviations"] or ["None."]),
        ("Conditions", "kv", content["conditions"]),
        ("Result", "kv", [["stated sensitivity", stated["text"]],
                          ["coverage factor k", f"{stated['k']:.2f}" if stated.get("k") else "—"]]
         + ([["note", stated["note"]]] if stated.get("note") else [])),
        ("Per level", "table", content["levels"]),
        ("", "note", "Linearity: " + content["linearity"]["text"] + ". S_sh, the peak ratio of ISO 16063-13, is "
                     "stated only at levels within that standard's scope."),
        ("Other key figures", "table", content["results"]),
        ("", "note", content["results_note"]),
        ("Traceability", "table", content["traceability"]),
        ("", "note", content["traceability_note"]),
        ("Statement of conformity", "text", content["conformity_statement"]),
        ("Shot files", "table", content["shots"]),
        ("Authorisation", "text", f"Authorised by {content['authorised_by']} ({content['signatory_role']}) on "
                                  f"{content['issued_utc'][:10]} (UTC). {content['statement']}"),
    ]


def _heading_rows(content: dict[str, Any]) -> list[list[str]]:
    rows = [["certificate number", content["number"]], ["date of issue", content["issued_utc"][:10] + " (UTC)"]]
    if content.get("replaces"):
        rows.append(["replaces", f"certificate {content['replaces']}, which is withdrawn"])
    lab = content["lab"]
    rows += [["laboratory", lab["name"]], ["address", lab["address"] or "—"]]
    if lab.get("accreditation"):
        rows.append(["accreditation", lab["accreditation"]])
    rows += [["customer", content["customer"]], ["customer's contact", content.get("customer_contact") or "—"]]
    return rows


def all_text(content: dict[str, Any]) -> str:
    """Every string the documents print (for the glyph check)."""
    out: list[str] = []

    def walk(x: Any) -> None:
        if isinstance(x, str):
            out.append(x)
        elif isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, list | tuple):
            for v in x:
                walk(v)

    walk(content)
    return "".join(out)


@lru_cache(maxsize=1)
def _fonts() -> tuple[tuple[str, frozenset[int]], ...]:
    """(family, the code points it draws) of the primary and every installed fallback font."""
    from fontTools.ttLib import TTFont
    from matplotlib import font_manager

    out = []
    for family in (PRIMARY_FONT, *FALLBACK_FONTS):
        try:
            path = font_manager.findfont(font_manager.FontProperties(family=family), fallback_to_default=False)
        except ValueError:
            continue
        try:
            font = TTFont(path, fontNumber=0, lazy=True)
            cmap = font.getBestCmap() or {}
        except Exception:  # a font file fontTools cannot read: not a fallback
            continue
        out.append((family, frozenset(cmap)))
    return tuple(out)


def check_drawable(text: str) -> list[str]:
    """The font families to draw `text` with; UndrawableText naming the characters none has."""
    fonts = _fonts()
    covered = set().union(*(cp for _f, cp in fonts)) if fonts else set()
    missing = sorted({ch for ch in text if ord(ch) >= 0x20 and ord(ch) not in covered and ch not in "\n\t"})
    if missing:
        shown = " ".join(f"{ch} (U+{ord(ch):04X})" for ch in missing[:8])
        raise UndrawableText(f"the PDF cannot draw {shown}{' …' if len(missing) > 8 else ''}: no installed font has "
                             f"them (install e.g. fonts-noto-cjk for CJK, fonts-noto-color-emoji or fonts-symbola for "
                             f"emoji); the HTML and the DCC carry them")
    return [family for family, _cp in fonts]


def pdf_bytes(content: dict[str, Any]) -> bytes:
    """The certificate as PDF pages (module doc)."""
    from matplotlib.backends.backend_pdf import PdfPages

    title = f"{content['title']} {content['number']}"
    with _fonts_in_force(content):
        buffer = io.BytesIO()
        with PdfPages(buffer, metadata={"Title": title, "Subject": f"calibration of {content['serial']}",
                                        "Creator": "hopkinson", "CreationDate": None}) as pdf:
            for fig in pages(content):
                pdf.savefig(fig)
    return buffer.getvalue()


def png_pages(content: dict[str, Any], dpi: int = 70) -> list[bytes]:
    """The same pages as PNG images (for looking at them)."""
    out = []
    with _fonts_in_force(content):
        for fig in pages(content):
            buffer = io.BytesIO()
            fig.savefig(buffer, format="png", dpi=dpi)
            out.append(buffer.getvalue())
    return out


def _fonts_in_force(content: dict[str, Any]) -> Any:
    from matplotlib import rc_context

    return rc_context({"font.family": check_drawable(all_text(content)), "pdf.fonttype": 42})


def pages(content: dict[str, Any]) -> list[Any]:
    """The certificate's pages as figures (module doc; call with the fonts in force)."""
    from hopkinson.reports.layout import TextPages, new_figure

    title = f"{content['title']} {content['number']}"
    def continued(fig: Any) -> float:
        fig.text(0.5, 0.975, f"{title} (continued)", ha="center", va="top", fontsize=8, color="#555")
        return 40.0

    book = TextPages(new_figure(), continued=continued)
    book.centred(title, 15.0)
    if content.get("specimen"):
        book.centred(content["specimen"].upper(), 10.0)
    book.space(6)
    for heading, kind, data in sections(content):
        if heading:
            book.heading(heading)
        if kind == "kv":
            book.table(None, data, size=8.5, widths=[1, 3])
        elif kind == "table":
            book.table(data["header"], data["rows"], size=7.5) if data["rows"] else book.paragraph("—")
        elif kind == "list":
            for item in data:
                book.paragraph(f"• {item}", size=8.5)
        elif kind == "text":
            book.paragraph(data, size=8.5)
        else:
            book.paragraph(data, size=7.0, colour="#444")
    book.space(24)
    book.paragraph("Signature: ______________________________", size=9)
    book.space(12)
    book.centred(f"— {content['end']} —", 9.0)
    total = len(book.pages)
    for n, fig in enumerate(book.pages, start=1):
        if content.get("specimen"):  # across every page, under the text
            fig.text(0.5, 0.5, "SPECIMEN · SIMULATED", ha="center", va="center", rotation=45, fontsize=48,
                     color="#c00", alpha=0.18, zorder=-1)
        fig.text(0.5, 0.02, f"{content['number']} · page {n} of {total}", ha="center", fontsize=7, color="#555")
    return book.pages


def html_text(content: dict[str, Any]) -> str:
    """The certificate as one HTML page (module doc)."""
    from hopkinson.reports.writers import HTML_CSS, html_table

    e = html.escape
    title = f"{content['title']} {content['number']}"
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{e(title)}</title>"
             f"<style>{HTML_CSS}</style></head><body><h1>{e(title)}</h1>"]
    if content.get("specimen"):
        parts.append(f"<p class='specimen' style='color:#c00;font-weight:bold;border:2px solid #c00;padding:0.5em'>"
                     f"{e(content['specimen'])}</p>")
    for heading, kind, data in sections(content):
        if heading:
            parts.append(f"<h2>{e(heading)}</h2>")
        if kind == "kv":
            parts.append(html_table(None, data, "kv"))
        elif kind == "table":
            parts.append(html_table(data["header"], data["rows"]) if data["rows"] else "<p>—</p>")
        elif kind == "list":
            parts.append("<ul>" + "".join(f"<li>{e(item)}</li>" for item in data) + "</ul>")
        else:
            parts.append(f"<p class='{'note' if kind == 'note' else ''}'>{e(data)}</p>")
    parts.append("<p>Signature: ______________________________</p>")
    parts.append(f"<p style='text-align:center'>— {e(content['end'])} · {e(content['number'])} · page 1 of 1 —</p>"
                 "</body></html>\n")
    return "\n".join(parts)
