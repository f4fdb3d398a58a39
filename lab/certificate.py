"""Calibration certificates (ISO/IEC 17025:2017 §7.8): what one says, and its PDF and HTML.

`certificate_content` gathers, from the lab's record, everything a certificate states: its
number (filled in when issued: `LabRepository.issue_certificate` allocates it), the lab and the
customer, the item and its identification, the method (the paper, this software's version),
the conditions, the results with U and k (the campaign's shots combined: reports.statistics),
the traceability of the reference chain (each item's certificate), the statement of conformity
with its decision rule (lab.history), who authorised it, and which shot files (by SHA-256) it
rests on. The content is stored with the number as issued and is never changed; the files are
drawn from it (`write_certificate`), so a copy printed again says the same.

A campaign with shots made by the simulator gets no certificate: only a *specimen* (`specimen=
True`), numbered in its own series (`<prefix>-SIM-<year>-<NNNN>`, never a certificate's
number) and marked on every page as simulated data, not a calibration.
"""

from __future__ import annotations

import html
from dataclasses import dataclass
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Any

from hopkinson.analysis.key_figures import Figure
from hopkinson.lab.errors import LabError
from hopkinson.lab.history import DECISION_RULES, conformity_of
from hopkinson.lab.repository import Calibration, LabRepository, SensorInfo
from hopkinson.reports.statistics import COMBINATION_NOTE, COMBINED, combine

from hopkinson.fileio import atomic_write

METHOD = ("Primary shock calibration on a Hopkinson bar with laser Doppler interferometry (ISO 16063-13); the "
          "accelerometer's dynamic model (order, poles), its band of small distortion (FBSD, ±5 % and ±10 %) "
          "and its dynamic compensation model identified after Z. Yang, Q. Wang, H. Du, J. Fan, J. Liang, "
          "\"Dynamic characterization method of accelerometers based on the Hopkinson bar calibration system\"; "
          "uncertainty by Monte Carlo (GUM Supplement 1), combined across shots (GUM 5.1, G.4).")
FORMATS = (".pdf", ".html")
SPECIMEN_MARK = "SPECIMEN: simulated data, not a calibration"
UNCONDITIONAL = ("This certificate shall not be reproduced except in full without the written approval of the "
                 "laboratory. The results relate only to the item calibrated, at the conditions stated.")


@dataclass(frozen=True)
class LabIdentity:
    """The lab as its certificates name it (the rig configuration's [lab])."""

    name: str
    address: str = ""
    accreditation: str = ""
    certificate_prefix: str = "HB"
    decision_rule: str = "simple"


def _fmt(figure: Figure, scale: float, unit: str) -> tuple[str, str]:
    text = figure.format(scale, unit=unit)
    value, _, expanded = text.partition(" ± ")
    return value, expanded or "—"


def _specimen_mark(simulated: int, shots: int) -> str:
    """The specimen's mark, with how many of its shots were simulated (when any)."""
    return SPECIMEN_MARK + (f" ({simulated} of {shots} shots simulated)" if simulated else "")


def certificate_content(repo: LabRepository, campaign: str, lab: LabIdentity, *, customer: str = "", conditions: str = "",
                        authorised_by: str, software_version: str, today: date | None = None,
                        specimen: bool = False) -> dict[str, Any]:
    """Everything the certificate of `campaign` (a recorded run folder's name) states, without
    its number. LabError when there is nothing to certify, the reference chain is overdue, or
    a shot was simulated and `specimen` is False (module docstring)."""
    serial = repo.campaign_sensor(campaign)
    if serial is None:
        raise LabError(f"campaign {campaign}: not in the lab's record (run `hopkinson lab import` on its folder)")
    sensor = repo.sensor(serial)
    assert sensor is not None
    calibrations = repo.calibrations(serial, campaign=campaign)
    if not calibrations:
        raise LabError(f"campaign {campaign}: no analysed shot to certify")
    simulated = [c.shot_name or c.shot_uuid for c in calibrations if c.simulated]
    if simulated and not specimen:
        raise LabError(f"campaign {campaign}: {len(simulated)} of its {len(calibrations)} shots were made by the "
                       f"simulator ({', '.join(simulated[:3])}{' …' if len(simulated) > 3 else ''}): no certificate; "
                       "--specimen issues a specimen marked as simulated data")
    today = today or datetime.now(UTC).date()
    rigs = sorted({c.rig for c in calibrations})
    chain = [link for rig in rigs for link in repo.reference_chain(rig)]
    overdue = [f"{link['item']} ({link['certificate']}, due {link['due']})" for link in chain
               if link["due"] and date.fromisoformat(link["due"]) < min(_day(c.utc_time) for c in calibrations)]
    if overdue:
        raise LabError(f"campaign {campaign}: reference chain overdue at the calibration: {'; '.join(overdue)}; "
                       f"no certificate")
    results, sensitivity, unit = _results(calibrations)
    conformity = conformity_of(sensitivity, unit, sensor, lab.decision_rule) if sensitivity else None
    first, last = calibrations[0].utc_time, calibrations[-1].utc_time
    peaks = [c.peak_acceleration_m_s2 for c in calibrations if c.peak_acceleration_m_s2]
    return {
        "title": "Specimen calibration certificate" if specimen else "Calibration certificate",
        "specimen": _specimen_mark(len(simulated), len(calibrations)) if specimen else "",
        "lab": {"name": lab.name or "(lab name not configured: [lab] name)", "address": lab.address,
                "accreditation": lab.accreditation},
        "customer": customer or sensor.owner or "—",
        "item": _item(sensor),
        "method": METHOD,
        "software_version": software_version,
        "conditions": [
            ["calibration date(s)", first[:10] if first[:10] == last[:10] else f"{first[:10]} to {last[:10]}"],
            ["rig", ", ".join(rigs)],
            ["campaign (run folder)", campaign],
            ["shots", str(len(calibrations))],
            ["peak acceleration", f"{min(peaks) / 9.80665:,.0f} g to {max(peaks) / 9.80665:,.0f} g" if peaks else "—"],
            ["operator(s)", ", ".join(sorted({c.operator for c in calibrations if c.operator})) or "—"],
            ["response unit", unit or "—"],
            ["environment", conditions or "not stated (not recorded by this system)"],
        ],
        "results": {"header": ["quantity", "value", "U", "k", "unit", "shots"], "rows": results},
        "results_note": COMBINATION_NOTE + " U is the expanded uncertainty for a coverage probability of about 95 %.",
        "traceability": {"header": ["reference item", "certificate", "issued by", "u (k = 1)", "due"],
                         "rows": [[link["item"], link["certificate"], link["issued_by"] or "—",
                                   f"{100 * link['u_rel']:.3g} %" if link["u_rel"] else "—", link["due"] or "—"]
                                  for link in chain]},
        "decision_rule": lab.decision_rule,
        "decision_rule_text": DECISION_RULES[lab.decision_rule],
        "conformity": conformity.verdict if conformity else "not stated",
        "conformity_statement": conformity.statement() if conformity else
        "No statement of conformity: the sensor's tolerance (and nominal sensitivity) are not in the record "
        "(`hopkinson lab sensor SERIAL --tolerance-percent …`).",
        "shots": {"header": ["shot", "UTC", "UUID"], "rows": [[c.shot_name, c.utc_time, c.shot_uuid]
                                                              for c in calibrations]},
        "serial": serial,
        "subject": campaign,
        "authorised_by": authorised_by,
        "statement": UNCONDITIONAL,
    }


def _day(utc: str) -> date:
    return datetime.fromisoformat(utc.replace("Z", "+00:00")).date()


def _item(sensor: SensorInfo) -> list[list[str]]:
    nominal = (f"{sensor.nominal_sensitivity:g} {sensor.sensitivity_unit}".strip()
               if sensor.nominal_sensitivity is not None else "—")
    return [["item", "accelerometer (shock)"], ["model", sensor.model or "—"], ["serial number", sensor.serial],
            ["owner", sensor.owner or "—"], ["nominal sensitivity", nominal],
            ["tolerance", f"±{sensor.tolerance_percent:g} %" if sensor.tolerance_percent is not None else "—"]]


def _results(calibrations: list[Calibration]) -> tuple[list[list[str]], Figure | None, str]:
    unit = calibrations[-1].response_unit
    rows, sensitivity = [], None
    for key, label, shown_unit, scale, _attr in COMBINED:
        combined = combine([c.figures.get(key) for c in calibrations])
        if combined.mean is None:
            continue
        known_u = bool(combined.expanded)  # none (or zero: identical values without their own u) is not stated
        figure = combined.figure() if known_u else Figure(combined.mean)
        if key == "sensitivity":
            sensitivity = figure
        value, expanded = _fmt(figure, scale, "")
        rows.append([label, value, expanded, f"{combined.k:.2f}" if known_u else "—",
                     shown_unit if shown_unit != "× nominal" or unit == "m/s^2" else f"{unit}/(m/s²)",
                     str(combined.n)])
    return rows, sensitivity, unit


def with_number(content: dict[str, Any], number: str, issued_utc: str, replaces: str = "") -> dict[str, Any]:
    """The content as issued: its number, date and the certificate it replaces."""
    return dict(content, number=number, issued_utc=issued_utc, replaces=replaces)


# -- files --------------------------------------------------------------------------------------
def write_certificate(content: dict[str, Any], path: str | Path) -> Path:
    """The issued certificate as .pdf or .html (atomically; from the stored content only)."""
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise LabError(f"{path}: a certificate is .pdf or .html")
    if path.suffix.lower() == ".pdf":
        _write_pdf(content, path)
    else:
        atomic_write(path, _html(content))
    return path


def _heading_rows(content: dict[str, Any]) -> list[list[str]]:
    rows = [["certificate number", content["number"]], ["date of issue", content["issued_utc"][:10]]]
    if content.get("replaces"):
        rows.append(["replaces", f"certificate {content['replaces']}, which is withdrawn"])
    lab = content["lab"]
    rows += [["laboratory", lab["name"]], ["address", lab["address"] or "—"]]
    if lab.get("accreditation"):
        rows.append(["accreditation", lab["accreditation"]])
    rows.append(["customer", content["customer"]])
    return rows


def _sections(content: dict[str, Any]) -> list[tuple[str, str, Any]]:
    """(heading, kind, data): the certificate's order, for both formats."""
    return [
        ("", "kv", _heading_rows(content)),
        ("Item calibrated", "kv", content["item"]),
        ("Method", "text", f"{content['method']} Software: hopkinson {content['software_version']}."),
        ("Conditions", "kv", content["conditions"]),
        ("Results", "table", content["results"]),
        ("", "note", content["results_note"]),
        ("Traceability", "table", content["traceability"]),
        ("", "note", "The reference chain's own certificates, as recorded for the rig; its uncertainties enter "
                     "the results' uncertainty budget." if content["traceability"]["rows"] else
                     "No reference chain is recorded for the rig ([[lab.reference_chain]] in its configuration): "
                     "the results' traceability is not stated."),
        ("Statement of conformity", "text", content["conformity_statement"]),
        ("Shot files", "table", content["shots"]),
        ("Authorisation", "text", f"Authorised by {content['authorised_by']} on {content['issued_utc'][:10]}. "
                                  f"{content['statement']}"),
    ]


def _write_pdf(content: dict[str, Any], path: Path) -> None:
    from hopkinson.reports.layout import TextPages, new_figure
    from matplotlib.backends.backend_pdf import PdfPages

    def continued(fig: Any) -> float:
        fig.text(0.5, 0.975, f"{content['title']} {content['number']} (continued)", ha="center", va="top",
                 fontsize=8, color="#555")
        return 40.0

    pages = TextPages(new_figure(), continued=continued)
    pages.centred(f"{content['title']} {content['number']}", 15.0)
    if content.get("specimen"):
        pages.centred(content["specimen"].upper(), 10.0)
    pages.space(6)
    for heading, kind, data in _sections(content):
        if heading:
            pages.heading(heading)
        if kind == "kv":
            pages.table(None, data, size=8.5, widths=[1, 3])
        elif kind == "table":
            pages.table(data["header"], data["rows"], size=7.5) if data["rows"] else pages.paragraph("—")
        elif kind == "text":
            pages.paragraph(data, size=8.5)
        else:
            pages.paragraph(data, size=7.0, colour="#444")
    pages.space(24)
    pages.paragraph("Signature: ______________________________", size=9)
    for n, fig in enumerate(pages.pages, start=1):
        if content.get("specimen"):  # across every page, under the text
            fig.text(0.5, 0.5, "SPECIMEN · SIMULATED", ha="center", va="center", rotation=45, fontsize=48,
                     color="#c00", alpha=0.18, zorder=-1)
        fig.text(0.5, 0.02, f"{content['number']} · page {n} of {len(pages.pages)}", ha="center", fontsize=7,
                 color="#555")

    def write(tmp: Path) -> None:
        with PdfPages(tmp, metadata={"Title": f"{content['title']} {content['number']}",
                                     "Subject": f"calibration of {content['serial']}", "Creator": "hopkinson"}) as pdf:
            for fig in pages.pages:
                pdf.savefig(fig)

    atomic_write(path, write)


def _html(content: dict[str, Any]) -> str:
    from hopkinson.reports.writers import HTML_CSS, html_table

    e = html.escape
    title = f"{content['title']} {content['number']}"
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{e(title)}</title>"
             f"<style>{HTML_CSS}</style></head><body><h1>{e(title)}</h1>"]
    if content.get("specimen"):
        parts.append(f"<p class='specimen' style='color:#c00;font-weight:bold;border:2px solid #c00;padding:0.5em'>"
                     f"{e(content['specimen'])}</p>")
    for heading, kind, data in _sections(content):
        if heading:
            parts.append(f"<h2>{e(heading)}</h2>")
        if kind == "kv":
            parts.append(html_table(None, data, "kv"))
        elif kind == "table":
            parts.append(html_table(data["header"], data["rows"]) if data["rows"] else "<p>—</p>")
        else:
            parts.append(f"<p class='{'note' if kind == 'note' else ''}'>{e(data)}</p>")
    parts.append("<p>Signature: ______________________________</p></body></html>\n")
    return "\n".join(parts)
