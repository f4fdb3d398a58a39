"""What a calibration certificate states (ISO/IEC 17025:2017 §7.8, ISO 16063-13/-22), gathered
from the lab's record inside the issuing unit of work (lab.issuing). The content is stored with
the number as issued and never changed; every document (PDF, HTML: reports.certificate_pages;
DCC XML: lab.dcc) is drawn from it, so a copy printed again says the same.

It states: the lab, the customer and the job record (receipt date, condition as received,
location); the item; the method, in words that do not depend on which sensitivity the
analysis states; a deviations section, filled in automatically where the shots lie beyond the
scope of ISO 16063-13 (peak acceleration above 100 km/s², pulse shorter than 0.05 ms); the
conditions (amplifier, mounting, environment); the results in the sensor's own unit: one
stated sensitivity (the one the shots' key figures state, and the one the statement of
conformity judges) with U and k, a per-level table, the amplitude linearity of the quasi-static
gain (the campaign statistics' line: reports.statistics.campaign_linearity), the shock sensitivity
S_sh only at levels within ISO 16063-13's scope; the reference chain, whose u values must be
the ones the uncertainty budget used (refused otherwise); who authorised it, with their role
from the lab's list of signatories (anyone else is refused); the shot files it rests on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Any

from hopkinson.analysis.key_figures import Figure
from hopkinson.analysis.static_gain import QUASI_STATIC
from hopkinson.lab import schema as t
from hopkinson.lab.errors import LabError
from hopkinson.lab.history import (
    DECISION_RULES,
    Calibration,
    Level,
    calibrations_of,
    judge,
)
from hopkinson.lab.repositories import SensorInfo, ShotResult
from hopkinson.lab.uow import UnitOfWork
from hopkinson.reports.statistics import (
    COMBINATION_NOTE,
    COMBINED,
    campaign_linearity,
    static_gain_point,
)

METHOD = ("Primary shock calibration by comparison of the accelerometer's response with the acceleration of "
          "the end face of a Hopkinson bar measured by laser Doppler interferometry, after the principle of "
          "ISO 16063-13. The accelerometer's dynamic model (order, poles), its band of small distortion (FBSD, "
          "±5 % and ±10 %) and its dynamic compensation model are identified after Z. Yang, Q. Wang, H. Du, "
          "J. Fan, J. Liang, \"Dynamic characterization method of accelerometers based on the Hopkinson bar "
          "calibration system\". Uncertainty by Monte Carlo (GUM Supplement 1), combined across shots "
          "(GUM 5.1, G.4).")
ISO_16063_13_MAX_PEAK_M_S2 = 100e3  # ISO 16063-13:2001, scope: up to 100 km/s²
ISO_16063_13_MIN_PULSE_S = 0.05e-3  # ... and pulse durations of at least 0.05 ms
SPECIMEN_MARK = "SPECIMEN: simulated data, not a calibration"
UNCONDITIONAL = ("This certificate shall not be reproduced except in full without the written approval of the "
                 "laboratory. The results relate only to the item calibrated, at the conditions stated.")
END_MARK = "End of certificate"
BUDGET_NAMES = {"grating_pitch_rel": "grating pitch", "interferometer_rel": "interferometer",
                "amplifier_gain_rel": "amplifier gain", "digitizer_gain_rel": "digitizer gain"}


@dataclass(frozen=True)
class LabIdentity:
    """The lab as its certificates name it (the rig configuration's [lab])."""

    name: str
    address: str = ""
    accreditation: str = ""
    certificate_prefix: str = "HB"
    decision_rule: str = "simple"
    signatories: dict[str, str] = field(default_factory=dict)  # name -> role
    country: str = ""  # ISO 3166-1 alpha-2, for the DCC

    def role_of(self, name: str, specimen: bool) -> str:
        """The signatory's role; LabError for anyone not on the list (a specimen: anyone named)."""
        wanted = " ".join(name.split()).casefold()
        for person, role in self.signatories.items():
            if " ".join(person.split()).casefold() == wanted:
                return role
        if specimen:
            return "not an authorised signatory (specimen)"
        listed = ", ".join(self.signatories) or "none: [[lab.signatories]] in the configuration"
        raise LabError(f"--authorised-by {name!r}: not an authorised signatory of the lab (authorised: {listed})")


@dataclass(frozen=True)
class Request:
    """What the person issuing adds to the record's content."""

    authorised_by: str
    software_version: str
    customer: str = ""
    conditions: str = ""
    deviations: tuple[str, ...] = ()
    specimen: bool = False
    today: date | None = None


def certificate_content(uow: UnitOfWork, campaign: t.Campaign, lab: LabIdentity, request: Request) -> dict[str, Any]:
    """Everything the certificate of `campaign` states, without its number (module doc);
    LabError when there is nothing to certify or a rule forbids it."""
    sensor_row = uow.session.get(t.Sensor, campaign.sensor_id)
    sensor = uow.sensors.info(sensor_row.serial)
    assert sensor is not None
    results = uow.shots.results(campaign=campaign)
    if not results:
        raise LabError(f"campaign {campaign.name}: no analysed shot to certify")
    (calibration,) = calibrations_of(results, sensor)
    role = lab.role_of(request.authorised_by, request.specimen)
    job = uow.campaigns.job(campaign)
    if job is None and not request.specimen:
        raise LabError(f"campaign {campaign.name}: no job record (date of receipt, condition as received, location): "
                       f"`hopkinson lab job {campaign.uuid} --received YYYY-MM-DD --condition … --location …`")
    chain = _reference_chain(uow, results)
    _check_chain_against_budget(campaign, chain, results)
    _check_chain_due(campaign, chain, results)
    stated, unit, ratio_note = _stated(calibration, sensor)
    conformity = judge(calibration, sensor, lab.decision_rule)
    levels = calibration.levels
    first, last = calibration.first_utc, calibration.utc_time
    simulated = sum(r.simulated for r in results)
    return {
        "title": "Specimen calibration certificate" if request.specimen else "Calibration certificate",
        "specimen": (SPECIMEN_MARK + (f" ({simulated} of {len(results)} shots simulated)" if simulated else ""))
        if request.specimen else "",
        "lab": {"name": lab.name or "(lab name not configured: [lab] name)", "address": lab.address,
                "accreditation": lab.accreditation},
        "customer": request.customer or (job.customer if job and job.customer else sensor.owner) or "—",
        "customer_contact": job.customer_contact if job and job.customer_contact else "—",
        "job": [["date of receipt", job.received if job and job.received else "—"],
                ["condition as received", job.condition if job and job.condition else "—"],
                ["where the calibration was done", job.location if job and job.location else "—"],
                ["calibration date(s) (UTC)", _dates(first, last)]],
        "item": _item(sensor),
        "method": METHOD,
        "software_version": request.software_version,
        "analysis_software": sorted({r.analysis_software for r in results} - {""}),
        "conditions": _conditions(calibration, campaign, job, request),
        "deviations": deviations(levels, results) + list(request.deviations),
        "stated": {"quantity": "sensitivity", "value": stated.value, "u": stated.u,
                   "U": stated.expanded, "k": _k(calibration), "unit": unit, "note": ratio_note,
                   "text": _value_text(stated, unit)},
        "results": _results(calibration),
        "results_note": COMBINATION_NOTE + " U is the expanded uncertainty for a coverage probability of about 95 %.",
        "levels": _level_table(levels, stated, calibration, unit),
        "levels_raw": _level_values(levels, stated, calibration),
        "linearity": _linearity(calibration.shots),
        "fbsd": {k: _figure_dict(calibration.figures.get(f"fbsd_{k}_hz")) for k in ("5", "10")},
        "traceability": {"header": ["reference item", "certificate", "issued by", "u (k = 1)", "due",
                                    "budget input"],
                         "rows": [[c["item"], c["certificate"], c.get("issued_by") or "—",
                                   f"{100 * c['u_rel']:.3g} %" if c.get("u_rel") else "—", c.get("due") or "—",
                                   BUDGET_NAMES.get(c.get("budget") or "", "not an input")] for c in chain]},
        "traceability_note": _chain_note(chain),
        "decision_rule": lab.decision_rule,
        "decision_rule_text": DECISION_RULES[lab.decision_rule],
        "conformity": conformity.verdict if conformity else "not stated",
        "conformity_statement": conformity.statement().replace(
            "sensitivity deviates", "the stated sensitivity deviates") if conformity else
        "No statement of conformity: the sensor's tolerance (and nominal sensitivity) are not in the record "
        "(`hopkinson lab sensor SERIAL --tolerance-percent …`).",
        "shots": {"header": ["shot", "UTC", "peak (km/s²)", "pulse (µs)", "UUID", "file SHA-256"],
                  "rows": [[r.shot_name, r.utc_time, _num(r.peak_acceleration_m_s2, 1e3, 4),
                            _num(r.pulse_width_s, 1e-6, 3), r.shot_uuid, r.file_sha256[:16] + "…"]
                           for r in results]},
        "serial": sensor.serial,
        "subject": campaign.name,
        "campaign_uuid": campaign.uuid,
        "authorised_by": request.authorised_by,
        "signatory_role": role,
        "statement": UNCONDITIONAL,
        "end": END_MARK,
    }


def _figure_dict(figure: Figure | None) -> dict[str, Any] | None:
    return None if figure is None else {"value": figure.value, "u": figure.u, "U": figure.expanded}


def _k(calibration: Calibration) -> float | None:
    from hopkinson.reports.statistics import combine

    return combine([s.figures.get("sensitivity") for s in calibration.shots]).k


def _dates(first: str, last: str) -> str:
    return first[:10] if first[:10] == last[:10] else f"{first[:10]} to {last[:10]}"


def _span(lo: float, hi: float, digits: int) -> str:
    a, b = f"{lo:,.{digits}g}", f"{hi:,.{digits}g}"
    return a if a == b else f"{a} to {b}"


def _num(value: float | None, scale: float, digits: int) -> str:
    return f"{value / scale:.{digits}g}" if value else "—"


def _value_text(figure: Figure, unit: str) -> str:
    text = figure.format(unit=unit)
    return text if figure.expanded is not None else f"{text} (no uncertainty stated)"


def _stated(calibration: Calibration, sensor: SensorInfo) -> tuple[Figure, str, str]:
    """The stated sensitivity in the sensor's unit when the record knows the scale, else as the
    response's unit; with a note saying which."""
    ratio = calibration.figures.get("sensitivity")
    if ratio is None:
        raise LabError(f"campaign {calibration.campaign}: no shot states a sensitivity; no certificate")
    if calibration.absolute is not None:
        note = "" if calibration.absolute_unit == sensor.sensitivity_unit or not sensor.sensitivity_unit else (
            f"in {calibration.absolute_unit}: the sensor's unit {sensor.sensitivity_unit!r} cannot be converted to")
        return calibration.absolute, calibration.absolute_unit, note
    if calibration.response_unit == "m/s^2":
        return ratio, "× nominal", ("as a ratio to the nominal sensitivity the rig scaled the response by: the "
                                    "record holds no scale to state it in the sensor's unit")
    return ratio, f"{calibration.response_unit}/(m/s²)", "at the conditioner's output"


def _item(sensor: SensorInfo) -> list[list[str]]:
    nominal = (f"{sensor.nominal_sensitivity:g} {sensor.sensitivity_unit}".strip()
               if sensor.nominal_sensitivity is not None else "—")
    return [["item", "accelerometer (shock)"], ["model", sensor.model or "—"], ["serial number", sensor.serial],
            ["owner", sensor.owner or "—"], ["nominal sensitivity", nominal],
            ["tolerance", f"±{sensor.tolerance_percent:g} %" if sensor.tolerance_percent is not None else "—"]]


def _conditions(calibration: Calibration, campaign: t.Campaign, job: t.Job | None, request: Request) -> list[list[str]]:
    contexts = [s.context for s in calibration.shots]
    amp = contexts[-1].get("amplifier") or {}
    gains = sorted({c.get("amplifier_gain") for c in contexts if c.get("amplifier_gain") is not None})
    peaks = [s.peak_acceleration_m_s2 for s in calibration.shots if s.peak_acceleration_m_s2]
    widths = [s.pulse_width_s for s in calibration.shots if s.pulse_width_s]
    instruments = contexts[-1].get("instruments") or {}
    return [
        ["rig", calibration.rig],
        ["campaign", f"{campaign.name} ({campaign.uuid})"],
        ["shots", str(len(calibration.shots))],
        ["peak acceleration", f"{_span(min(peaks) / 1e3, max(peaks) / 1e3, 4)} km/s²" if peaks else "—"],
        ["pulse duration", f"{_span(min(widths) * 1e6, max(widths) * 1e6, 3)} µs" if widths else "—"],
        ["operator(s)", calibration.operator or "—"],
        ["amplifier", ", ".join(x for x in (
            f"gain {', '.join(f'{g:g}' for g in gains)}" if gains else "",
            f"excitation {amp['excitation_v']:g} V" if amp.get("excitation_v") else "",
            f"low-pass {amp['lowpass_hz'] / 1e3:g} kHz" if amp.get("lowpass_hz") else "",
            str(amp.get("identity") or "")) if x) or "—"],
        ["mounting", (job.mounting if job and job.mounting else "") or str(contexts[-1].get("mounting") or "") or "—"],
        ["instruments", "; ".join(f"{k}: {v}" for k, v in sorted(instruments.items())) or "—"],
        ["environment", request.conditions or (job.environment if job and job.environment else "")
         or "not stated (not recorded by this system)"],
    ]


def deviations(levels: tuple[Level, ...], results: list[ShotResult]) -> list[str]:
    """The deviations from the method a certificate must state, found in the shots themselves."""
    out = []
    peaks = [r.peak_acceleration_m_s2 for r in results if r.peak_acceleration_m_s2]
    widths = [r.pulse_width_s for r in results if r.pulse_width_s]
    above = [p for p in peaks if p > ISO_16063_13_MAX_PEAK_M_S2]
    short = [w for w in widths if w < ISO_16063_13_MIN_PULSE_S]
    if above or short:
        parts = []
        if above:
            parts.append(f"{len(above)} of {len(peaks)} shots reached {_span(min(above) / 1e3, max(above) / 1e3, 4)} "
                         f"km/s², above the standard's 100 km/s²")
        if short:
            parts.append(f"{len(short)} of {len(widths)} pulses lasted {_span(min(short) * 1e6, max(short) * 1e6, 3)} "
                         f"µs, shorter than its 0.05 ms")
        out.append("Beyond the scope of ISO 16063-13: " + "; ".join(parts) + ". The method is applied beyond the "
                   "standard's scope; the shock sensitivity S_sh is not stated at those levels.")
    return out


def within_scope(level: Level) -> bool:
    return level.peak_m_s2 <= ISO_16063_13_MAX_PEAK_M_S2 and (level.pulse_width_s or 0.0) >= ISO_16063_13_MIN_PULSE_S


def _results(calibration: Calibration) -> dict[str, Any]:
    """The other key figures, combined (the stated sensitivity and S_sh have their own places)."""
    from hopkinson.reports.statistics import combine

    rows = []
    for key, label, unit, scale, _attr in COMBINED:
        if key in ("sensitivity", "shock_sensitivity"):
            continue
        combined = combine([s.figures.get(key) for s in calibration.shots])
        if combined.mean is None:
            continue
        known_u = bool(combined.expanded)
        figure = combined.figure() if known_u else Figure(combined.mean)
        value, _, expanded = figure.format(scale).partition(" ± ")
        rows.append([label, value, expanded or "—", f"{combined.k:.2f}" if known_u else "—", unit, str(combined.n)])
    return {"header": ["quantity", "value", "U", "k", "unit", "shots"], "rows": rows}


def _level_table(levels: tuple[Level, ...], stated: Figure, calibration: Calibration, unit: str) -> dict[str, Any]:
    """Per level: peak, pulse, shots, the stated sensitivity ± U in the stated unit, its
    deviation from the calibration's value, S_sh ± U where ISO 16063-13's scope holds."""
    ratio = calibration.figures.get("sensitivity")
    scale = stated.value / ratio.value if ratio is not None and ratio.value and stated.value else 1.0
    rows = []
    for n, level in enumerate(levels, start=1):
        s = level.combined("sensitivity")
        shown = Figure(s.value * scale, s.u * abs(scale) if s.u is not None else None,
                       (s.interval[0] * scale, s.interval[1] * scale) if s.interval else None) if s else None
        deviation = 100 * (s.value / ratio.value - 1) if s is not None and ratio is not None and ratio.value else None
        shock = level.combined("shock_sensitivity") if within_scope(level) else None
        rows.append([str(n), f"{level.peak_m_s2 / 1e3:,.4g}", _num(level.pulse_width_s, 1e-6, 3), str(len(level.shots)),
                     shown.format() if shown else "—", f"{deviation:+.2f}" if deviation is not None else "—",
                     (Figure(shock.value * scale, shock.u * abs(scale) if shock.u else None,
                             (shock.interval[0] * scale, shock.interval[1] * scale) if shock.interval else None).format()
                      if shock is not None else "— (outside ISO 16063-13)")])
    return {"header": ["level", "peak (km/s²)", "pulse (µs)", "shots", f"sensitivity ({unit})", "deviation (%)",
                       f"S_sh ({unit})"], "rows": rows}


def _level_values(levels: tuple[Level, ...], stated: Figure, calibration: Calibration) -> list[dict[str, Any]]:
    """The per-level table's numbers (for the DCC): peak, pulse, the stated sensitivity, U, k."""
    from hopkinson.reports.statistics import combine

    ratio = calibration.figures.get("sensitivity")
    scale = stated.value / ratio.value if ratio is not None and ratio.value and stated.value else 1.0
    out = []
    for n, level in enumerate(levels, start=1):
        c = combine([s.figures.get("sensitivity") for s in level.shots])
        out.append({"level": n, "peak_m_s2": level.peak_m_s2, "pulse_width_s": level.pulse_width_s,
                    "sensitivity": c.mean * scale if c.mean is not None else None,
                    "U": c.expanded * abs(scale) if c.expanded else None, "k": c.k})
    return out


def _linearity(shots: tuple[ShotResult, ...] | list[ShotResult]) -> dict[str, Any]:
    """The amplitude linearity (ISO 16063-22) the campaign's statistics give
    (reports.statistics.campaign_linearity): the straight line through each shot's quasi-static
    gain in the main pulse's direction against the amplitude it is measured at, with its U. Not
    the stated sensitivity (the model's DC gain) nor S_sh: neither means the same at every level.
    Shots recorded without a quasi-static gain (analysed, or imported, before it) are left out."""
    points = [p for r in shots if (p := static_gain_point(r.shot_name, r.static_gain, r.static_gain_amplitude_m_s2))]
    missing = [r.shot_name for r in shots if r.static_gain is None]
    fit, note = campaign_linearity(points)
    left = (f"; {len(missing)} of {len(shots)} shots hold no quasi-static gain in the record (analysed or imported "
            f"before it: analyse and import them again) and are left out ({', '.join(missing)})") if missing else ""
    sensitivity = (f"of the quasi-static sensitivity in the main pulse's direction: each shot's response, corrected "
                   f"for the sensor's identified dynamics, fitted to the reference acceleration over the frequencies "
                   f"where the sensor is quasi-static (its response within {100 * QUASI_STATIC:g} % of the static "
                   f"one), at the amplitude that gain is measured at (a weighted mean of |a| over the main pulse, "
                   f"below its peak). The stated sensitivity above is the model's DC gain: neither it nor S_sh "
                   f"means the same at every level, so neither is fitted here")
    if fit is None:
        why = note.rpartition("amplitude linearity: ")[2] or "no line"
        return {"text": f"not stated ({why}{left})", "sensitivity": sensitivity, "fit": None,
                "points": [vars(p) for p in points]}
    return {"text": f"{fit.text()}, U for about 95 % (ISO 16063-22), {sensitivity}{left}",
            "sensitivity": sensitivity, "fit": fit.to_dict(), "points": [vars(p) for p in points]}


def _reference_chain(uow: UnitOfWork, results: list[ShotResult]) -> list[dict[str, Any]]:
    """The reference chain as the shots' configuration held it (each certificate once), else as
    recorded for their rigs."""
    chain: dict[tuple[str, str], dict[str, Any]] = {}
    for r in results:
        for link in r.context.get("reference_chain") or ():
            chain.setdefault((str(link.get("item")), str(link.get("certificate"))), dict(link))
    if not chain:
        for rig in sorted({r.rig for r in results}):
            for link in uow.shots.reference_chain(rig):
                chain.setdefault((link["item"], link["certificate"]), link)
    return list(chain.values())


def _check_chain_against_budget(campaign: t.Campaign, chain: list[dict[str, Any]], results: list[ShotResult]) -> None:
    """LabError when a reference item's u is not the one the shots' uncertainty budget used."""
    for link in chain:
        key = link.get("budget") or ""
        if not key or not link.get("u_rel"):
            continue
        used = {r.context.get("uncertainty", {}).get(key) for r in results} - {None}
        wrong = sorted(u for u in used if abs(float(u) - float(link["u_rel"])) > 1e-12)
        if wrong:
            raise LabError(f"campaign {campaign.name}: the reference chain's {link['item']} ({link['certificate']}) "
                           f"states u = {100 * float(link['u_rel']):.3g} %, but its shots' uncertainty budget used "
                           f"{', '.join(f'{100 * float(u):.3g} %' for u in wrong)} ([uncertainty] {key}): the "
                           f"certificate's U would not rest on its traceability; make them one value; no certificate")


def _check_chain_due(campaign: t.Campaign, chain: list[dict[str, Any]], results: list[ShotResult]) -> None:
    first = min(_day(r.utc_time) for r in results)
    overdue = [f"{c['item']} ({c['certificate']}, due {c['due']})" for c in chain
               if c.get("due") and date.fromisoformat(str(c["due"])) < first]
    if overdue:
        raise LabError(f"campaign {campaign.name}: reference chain overdue at the calibration: {'; '.join(overdue)}; "
                       f"no certificate")


def _chain_note(chain: list[dict[str, Any]]) -> str:
    if not chain:
        return ("No reference chain is recorded for the rig ([[lab.reference_chain]] in its configuration): the "
                "results' traceability is not stated.")
    tied = [c for c in chain if c.get("budget")]
    return ("The reference chain's own certificates as the shots' configuration held them. "
            + (f"Their u values are the inputs of the uncertainty budget ({len(tied)} of {len(chain)} items; the "
               "certificate is refused when the two differ)." if tied else
               "None of the items is tied to an input of the uncertainty budget ([[lab.reference_chain]] budget)."))


def _day(utc: str) -> date:
    return datetime.fromisoformat(utc.replace("Z", "+00:00")).astimezone(UTC).date()


DOCUMENT_SUFFIXES = (".pdf", ".html", ".xml")


def render(content: dict[str, Any], suffix: str, lab: LabIdentity) -> bytes:
    """One document of an issued certificate: PDF, HTML or the DCC (XML, validated)."""
    from hopkinson.reports.certificate_pages import UndrawableText, html_text, pdf_bytes

    if suffix == ".pdf":
        try:
            return pdf_bytes(content)
        except UndrawableText as exc:
            raise LabError(f"{exc}; no certificate") from None
    if suffix == ".html":
        return html_text(content).encode("utf-8")
    if suffix == ".xml":
        from hopkinson.lab.dcc import dcc_bytes

        return dcc_bytes(content, lab.country)
    raise LabError(f"a certificate is written as {', '.join(DOCUMENT_SUFFIXES)}, not {suffix!r}")


def write_documents(content: dict[str, Any], paths: list[Path], lab: LabIdentity) -> list[Path]:
    """Render every document first, then write each atomically; when one cannot be written the
    ones written are removed (LabError naming the file): all of them or none."""
    from hopkinson.fileio import atomic_write

    rendered = [(Path(p), render(content, Path(p).suffix.lower(), lab)) for p in paths]
    written: list[Path] = []
    try:
        for path, data in rendered:
            atomic_write(path, data)
            written.append(path)
    except OSError as exc:
        for path in written:
            path.unlink(missing_ok=True)
        raise LabError(f"{exc.filename or path}: cannot be written ({exc.strerror or exc}); no certificate issued") from None
    return written
