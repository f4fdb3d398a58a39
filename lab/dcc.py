"""The Digital Calibration Certificate (PTB's DCC, schema 3.2.0, with D-SI 2.1.0 quantities)
drawn from a certificate's stored content (lab.certificate), and its validation against the
released XSDs shipped in lab/schemas (LGPL-3.0, PTB; no network at run time).

Built with lxml, element by element in the schema's order. No maintained Python library
writes DCCs: pydcc (Siemens/PTB) reads and validates them and says it does not write them;
dccXMLJSONConv only maps XML to JSON and back; dcclib converts, signs and validates. lxml's
libxml2 validator checks the result against the XSD before a number is issued.

What it holds: the administrative data (software, core data with the dates of receipt and of
the calibration, the item and its serial, the lab, the signatory with their role, the
customer, statements: conformity with its decision rule, deviations, the certificate replaced,
a specimen's mark), and one measurement result with the method, the software, the reference
chain as measuring equipment, the environment, and the results as D-SI quantities with U and
k: the stated sensitivity, the per-level table (peak, pulse, sensitivity), the FBSD edges and
the main mode.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path
from typing import Any

from hopkinson.analysis import sensitivity_units as units
from hopkinson.lab.errors import LabError

DCC = "https://ptb.de/dcc"
SI = "https://ptb.de/si"
SCHEMA_VERSION = "3.2.0"
SCHEMAS = Path(__file__).with_name("schemas")
LOCAL_IMPORTS = {"https://ptb.de/si/v2.1.0/SI_Format.xsd": "SI_Format_2_1_0.xsd",
                 "https://www.w3.org/TR/xmldsig-core/xmldsig-core-schema.xsd": "xmldsig-core-schema.xsd"}
CONFORMITY = {"pass": "pass", "fail": "fail", "conditional pass": "conditionalPass",
              "conditional fail": "conditionalFail"}
D_SI_PREFIX = {1e-12: r"\pico", 1e-9: r"\nano", 1e-6: r"\micro", 1e-3: r"\milli", 1.0: "", 1e3: r"\kilo"}


class DccInvalid(LabError):
    """A DCC that does not validate against the released schema (the first errors named)."""


@lru_cache(maxsize=1)
def schema() -> Any:
    """The DCC 3.2.0 schema with its imports resolved to the shipped copies."""
    from lxml import etree

    tree = etree.parse(str(SCHEMAS / "dcc_3_2_0.xsd"))
    for imp in tree.getroot().iter("{http://www.w3.org/2001/XMLSchema}import"):
        location = imp.get("schemaLocation")
        if location in LOCAL_IMPORTS:
            imp.set("schemaLocation", (SCHEMAS / LOCAL_IMPORTS[location]).as_uri())
    return etree.XMLSchema(tree)


def validate(xml: bytes) -> None:
    """DccInvalid naming the first errors unless `xml` is a valid DCC 3.2.0."""
    from lxml import etree

    doc = etree.fromstring(xml)
    s = schema()
    if not s.validate(doc):
        errors = "; ".join(f"line {e.line}: {e.message}" for e in list(s.error_log)[:3])
        raise DccInvalid(f"the DCC does not validate against PTB's schema {SCHEMA_VERSION}: {errors}; no certificate")


def _num(x: float) -> str:
    if not math.isfinite(x):
        raise DccInvalid(f"a result is not a finite number ({x}); no certificate")
    return repr(float(x))


def d_si_unit(unit: str) -> tuple[str, float] | None:
    """(D-SI unit, factor) for a sensitivity unit (analysis.sensitivity_units): value·factor in the D-SI unit,
    e.g. "mV/g" -> (r"\\milli\\volt\\second\\tothe{2}\\metre\\tothe{-1}", 1/9.80665); a ratio -> \\one."""
    if unit in ("× nominal", "", "1"):
        return r"\one", 1.0
    parsed = units.parse(unit)
    if parsed is None:
        return None
    prefix, kind, per_m_s2 = parsed
    base = r"\volt" if kind == "V" else r"\coulomb"
    return D_SI_PREFIX[prefix] + base + r"\second\tothe{2}\metre\tothe{-1}", 1.0 / per_m_s2


class _Builder:
    def __init__(self) -> None:
        from lxml.builder import ElementMaker

        self.d = ElementMaker(namespace=DCC, nsmap={"dcc": DCC, "si": SI})
        self.s = ElementMaker(namespace=SI, nsmap={"dcc": DCC, "si": SI})

    def text(self, tag: str, *lines: str) -> Any:
        return getattr(self.d, tag)(*(self.d.content(str(line), lang="en") for line in lines if str(line)))

    def real(self, label: str, value: float, unit: str, expanded: float | None = None, k: float | None = None) -> Any:
        parts = [self.s.label(label), self.s.value(_num(value)), self.s.unit(unit)]
        if expanded is not None and k is not None and expanded > 0:
            parts.append(self.s.expandedUnc(self.s.uncertainty(_num(expanded)), self.s.coverageFactor(_num(max(k, 1.0))),
                                            self.s.coverageProbability("0.95"), self.s.distribution("normal")))
        return self.s.real(*parts)

    def quantity(self, name: str, label: str, value: float, unit: str, expanded: float | None = None,
                 k: float | None = None) -> Any:
        return self.d.quantity(self.text("name", name), self.real(label, value, unit, expanded, k))


def dcc_bytes(content: dict[str, Any], country: str) -> bytes:
    """The DCC of an issued certificate's content (module doc), validated; DccInvalid otherwise."""
    from lxml import etree

    if not (len(country) == 2 and country.isalpha() and country.isupper()):
        raise DccInvalid(f"[lab] country: the DCC needs the lab's ISO 3166-1 country code (e.g. \"DE\"), got "
                         f"{country!r}; no certificate")
    b = _Builder()
    d = b.d
    first, last = _dates(content)
    job = dict(content["job"])
    received = job.get("date of receipt", "—")
    core = [d.countryCodeISO3166_1(country), d.usedLangCodeISO639_1("en"), d.mandatoryLangCodeISO639_1("en"),
            d.uniqueIdentifier(content["number"]),
            d.identifications(d.identification(d.issuer("calibrationLaboratory"), d.value(content["campaign_uuid"]),
                                               b.text("name", "campaign (calibration) identity")))]
    if _is_date(received):
        core.append(d.receiptDate(received))
    core += [d.beginPerformanceDate(first), d.endPerformanceDate(last), d.performanceLocation("laboratory"),
             d.issueDate(content["issued_utc"][:10])]
    item = dict(content["item"])
    lab = content["lab"]
    admin = d.administrativeData(
        d.dccSoftware(d.software(b.text("name", "hopkinson"), d.release(content["software_version"] or "unknown"),
                                 d.type("application"))),
        d.coreData(*core),
        d.items(d.item(b.text("name", "accelerometer (shock)"), d.manufacturer(b.text("name", "not stated")),
                       *([d.model(item["model"])] if item.get("model", "—") != "—" else []),
                       d.identifications(d.identification(d.issuer("manufacturer"), d.value(item["serial number"]),
                                                          b.text("name", "serial number"))))),
        d.calibrationLaboratory(d.contact(b.text("name", lab["name"]),
                                          d.location(b.text("further", lab["address"] or "not stated")))),
        d.respPersons(d.respPerson(d.person(b.text("name", content["authorised_by"])),
                                   d.role(content["signatory_role"]), d.mainSigner("true"))),
        d.customer(b.text("name", content["customer"]),
                   d.location(b.text("further", content.get("customer_contact") or "not stated"))),
        d.statements(*_statements(b, content)),
    )
    root = d.digitalCalibrationCertificate(admin, _measurement_results(b, content), schemaVersion=SCHEMA_VERSION)
    xml = etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)
    validate(xml)
    return xml


def _is_date(text: str) -> bool:
    from datetime import date

    try:
        date.fromisoformat(text)
        return True
    except ValueError:
        return False


def _dates(content: dict[str, Any]) -> tuple[str, str]:
    when = dict(content["job"]).get("calibration date(s) (UTC)", "")
    first, _, last = when.partition(" to ")
    return first, last or first


def _statements(b: _Builder, content: dict[str, Any]) -> list[Any]:
    d = b.d
    out = []
    conformity = CONFORMITY.get(content["conformity"])
    statement = [b.text("name", "statement of conformity"), b.text("declaration", content["conformity_statement"])]
    if conformity:
        statement = [b.text("name", "statement of conformity"), d.norm("ILAC-G8:2019"),
                     b.text("declaration", content["conformity_statement"]), d.conformity(conformity)]
    out.append(d.statement(*statement))
    for text in content["deviations"] or ["None."]:
        out.append(d.statement(b.text("name", "deviation from the method"), b.text("declaration", text)))
    out.append(d.statement(b.text("name", "traceability"), d.traceable("true" if content["traceability"]["rows"]
                                                                       else "false"),
                           b.text("declaration", content["traceability_note"])))
    if content.get("replaces"):
        out.append(d.statement(b.text("name", "replaces"),
                               b.text("declaration", f"certificate {content['replaces']}, which is withdrawn")))
    if content.get("specimen"):
        out.append(d.statement(b.text("name", "specimen"), b.text("declaration", content["specimen"])))
    out.append(d.statement(b.text("name", "reproduction"), b.text("declaration", content["statement"])))
    return out


def _measurement_results(b: _Builder, content: dict[str, Any]) -> Any:
    d = b.d
    stated = content["stated"]
    unit = d_si_unit(stated["unit"])
    if unit is None:
        raise DccInvalid(f"the stated sensitivity's unit {stated['unit']!r} has no D-SI form; no certificate")
    si_unit, factor = unit
    k = stated.get("k")
    results = [d.result(b.text("name", "stated sensitivity"),
                        d.data(b.quantity("sensitivity", "sensitivity", stated["value"] * factor, si_unit,
                                          stated["U"] * factor if stated.get("U") else None, k)))]
    levels = []
    for row in content["levels_raw"]:
        quantities = [b.quantity("peak acceleration", "peak_acceleration", row["peak_m_s2"], r"\metre\second\tothe{-2}")]
        if row.get("pulse_width_s"):
            quantities.append(b.quantity("pulse duration", "pulse_duration", row["pulse_width_s"], r"\second"))
        if row.get("sensitivity") is not None:
            quantities.append(b.quantity("sensitivity", "sensitivity", row["sensitivity"] * factor, si_unit,
                                         row["U"] * factor if row.get("U") else None, row.get("k")))
        levels.append(d.list(b.text("name", f"level {row['level']}"), *quantities))
    if levels:
        results.append(d.result(b.text("name", "per level"), d.data(d.list(*levels))))
    fbsd = [b.quantity(f"FBSD ±{level} %", f"fbsd_{level}", f["value"], r"\hertz", f.get("U"), 2.0)
            for level, f in sorted(content["fbsd"].items(), key=lambda kv: float(kv[0])) if f and f.get("value")]
    if fbsd:
        results.append(d.result(b.text("name", "band of small distortion"), d.data(*fbsd)))
    methods = d.usedMethods(d.usedMethod(b.text("name", "primary shock calibration, Hopkinson bar"),
                                         b.text("description", content["method"]), d.norm("ISO 16063-13")))
    software = d.usedSoftware(d.software(b.text("name", "hopkinson"), d.release(content["software_version"] or "unknown")))
    equipment = [d.measuringEquipment(b.text("name", row[0]), b.text("description", f"certificate {row[1]} by {row[2]}; "
                                                                                    f"u (k = 1) {row[3]}; due {row[4]}"))
                 for row in content["traceability"]["rows"]]
    environment = dict(content["conditions"]).get("environment", "not stated")
    parts = [b.text("name", "shock calibration"), methods, software]
    if equipment:
        parts.append(d.measuringEquipments(*equipment))
    parts.append(d.influenceConditions(d.influenceCondition(b.text("name", "environment"),
                                                            d.data(b.text("text", environment)))))
    parts.append(d.results(*results))
    return d.measurementResults(d.measurementResult(*parts))
