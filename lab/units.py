"""A sensor's sensitivity in its own unit: the rig measures volts at the conditioner's input
per m/s² (or, for a charge amplifier, its input unit); a certificate states pC/(m/s²), mV/g,
µV/(m/s²) … `to_unit` converts between such units (SI prefixes, V or C over m/s², g or km/s²)
and refuses what it cannot convert rather than guess. Hand-written: the few units a shock
accelerometer's sensitivity is stated in need no units library."""

from __future__ import annotations

import re

STANDARD_GRAVITY_M_S2 = 9.80665  # g_n (CGPM 1901)
PREFIXES = {"p": 1e-12, "n": 1e-9, "µ": 1e-6, "μ": 1e-6, "u": 1e-6, "m": 1e-3, "": 1.0, "k": 1e3}
PER = {"m/s²": 1.0, "m/s^2": 1.0, "m/s2": 1.0, "(m/s²)": 1.0, "(m/s^2)": 1.0, "(m/s2)": 1.0, "ms^-2": 1.0,
       "g": STANDARD_GRAVITY_M_S2, "g_n": STANDARD_GRAVITY_M_S2, "gn": STANDARD_GRAVITY_M_S2,
       "km/s²": 1e3, "(km/s²)": 1e3, "km/s^2": 1e3, "(km/s^2)": 1e3}
_UNIT = re.compile(r"^\s*([pnµμumk]?)(V|C)\s*/\s*(.+?)\s*$")


def parse(unit: str) -> tuple[float, str, float] | None:
    """(numerator prefix factor, "V" or "C", m/s² per denominator unit), or None when unknown."""
    m = _UNIT.match(unit or "")
    if m is None or m.group(3).replace(" ", "") not in PER:
        return None
    return PREFIXES[m.group(1)], m.group(2), PER[m.group(3).replace(" ", "")]


def factor(from_unit: str, to_unit: str) -> float | None:
    """x [from_unit] · factor = x [to_unit]; None when either is unknown or their kinds differ."""
    a, b = parse(from_unit), parse(to_unit)
    if a is None or b is None or a[1] != b[1]:
        return None
    return (a[0] / a[2]) / (b[0] / b[2])
