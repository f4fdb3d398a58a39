"""The set-up's sensor against the lab's record: when the technician names a serial the record
knows, its nominal sensitivity (in its unit) and tolerance are compared with the set-up's, before
anything is fired. A nominal that differs by more than NOMINAL_MATCH_REL is said at once (another
sensor's nominal typed in); a tolerance the set-up lacks is taken from the record. Runs on the panel's background worker (`record_advice`)."""

from __future__ import annotations

from dataclasses import dataclass

from hopkinson.analysis.sensitivity_units import UNITS, canonical_name

NOMINAL_MATCH_REL = 0.01  # nominals within 1 % are the same nominal (rounding on a data sheet)


@dataclass(frozen=True)
class RecordAdvice:
    """What the record says about the set-up's sensor: a message (level "" for none) and the
    tolerance to put into the set-up (None: leave it)."""

    level: str
    text: str
    tolerance_percent: float | None = None


def record_advice(url: str, serial: str, nominal_si: float, tolerance_percent: float | None) -> RecordAdvice:
    """Compare the set-up's nominal (SI input units per m/s²) and tolerance with the record's
    data of `serial` (module docstring); nothing to say when the record does not know it."""
    from hopkinson.lab.repository import open_repository

    with open_repository(url) as repo:
        sensor = repo.sensor(serial)
    if sensor is None:
        return RecordAdvice("", "")
    fill = sensor.tolerance_percent if tolerance_percent is None and sensor.tolerance_percent else None
    unit = UNITS.get(canonical_name(sensor.sensitivity_unit or ""))
    if sensor.nominal_sensitivity and unit is not None:
        recorded_si = unit.to_si(sensor.nominal_sensitivity)
        if abs(nominal_si / recorded_si - 1.0) > NOMINAL_MATCH_REL:
            return RecordAdvice("warning", f"{serial}: the set-up's nominal {unit.from_si(nominal_si):.4g} {unit.name} "
                                           f"differs from the lab's record, {sensor.nominal_sensitivity:.4g} "
                                           f"{unit.name}: check the data sheet before ARM.", fill)
        return RecordAdvice("ok", f"{serial}: nominal {sensor.nominal_sensitivity:.4g} {unit.name} as in the lab's "
                                  "record" + (f"; its tolerance ±{fill:g} % taken from it." if fill else "."), fill)
    if fill:
        return RecordAdvice("info", f"{serial}: tolerance ±{fill:g} % taken from the lab's record.", fill)
    return RecordAdvice("", "")
