"""Sensitivity units: what an accelerometer's sensitivity is written in, and its SI value.

The analysis scales a sensor's conditioner output by 1/(gain × nominal sensitivity): the gain
is output volts per *input unit* (volts for a voltage sensor, coulombs for a charge sensor)
and the sensitivity is input units per m/s² (`AnalysisOptions.sensitivity_v_per_m_s2`, its SI
value). A lab writes sensitivities as its data sheets do: mV/g, pC/(m/s²), µV/(m/s²) …; each
`SensitivityUnit` here says which input it measures and what one of it is in SI, so a value
entered in the sensor's own unit becomes the SI value the analysis takes, and a DC gain
relative to nominal becomes an absolute sensitivity again in that unit.

Plausible values. A sensitivity outside `PLAUSIBLE_SI[input]` (SI units per m/s²) is almost
certainly a typing or unit error (a charge sensor of 10 000 pC/(m/s²), a voltage sensor of
0.00001 µV/(m/s²)); `check_plausible` refuses it naming the unit and the range in that unit.
Light: no NumPy.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

G_M_S2 = 9.80665  # standard gravity: 1 g in m/s²

# SI input units per m/s² that a shock accelerometer's sensitivity may plausibly have:
# voltage sensors 0.1 nV/(m/s²) … 0.1 V/(m/s²) (≈ 1 nV/g … 1 V/g); charge sensors
# 10⁻¹⁶ … 10⁻⁹ C/(m/s²) (0.0001 … 1000 pC/(m/s²)).
PLAUSIBLE_SI = {"V": (1e-10, 1e-1), "C": (1e-16, 1e-9)}


@dataclass(frozen=True)
class SensitivityUnit:
    """A sensitivity unit: its name as shown, the conditioner input it measures ("V" or "C"),
    and the SI value (input units per m/s²) of one of it."""

    name: str
    input_unit: str
    si: float

    def to_si(self, value: float) -> float:
        """A sensitivity in this unit as SI input units per m/s²."""
        return value * self.si

    def from_si(self, value_si: float) -> float:
        """An SI sensitivity (input units per m/s²) in this unit."""
        return value_si / self.si

    def plausible_range(self) -> tuple[float, float]:
        """The plausible sensitivities (PLAUSIBLE_SI) in this unit."""
        low, high = PLAUSIBLE_SI[self.input_unit]
        return self.from_si(low), self.from_si(high)


def _units() -> dict[str, SensitivityUnit]:
    per_m_s2 = {"V": 1.0, "mV": 1e-3, "µV": 1e-6, "pC": 1e-12, "fC": 1e-15}
    out: dict[str, SensitivityUnit] = {}
    for prefix, scale in per_m_s2.items():
        kind = "C" if prefix.endswith("C") else "V"
        out[f"{prefix}/(m/s²)"] = SensitivityUnit(f"{prefix}/(m/s²)", kind, scale)
        out[f"{prefix}/g"] = SensitivityUnit(f"{prefix}/g", kind, scale / G_M_S2)
    return out


UNITS: dict[str, SensitivityUnit] = _units()
DEFAULT_UNIT = "µV/(m/s²)"  # the unit of sensitivities that recorded none (the analysis' SI value, shown in µV)
# the same units written in ASCII (a TOML file, a command line)
_ALIASES = {"u": "µ", "^2": "²", "s2": "s²"}


def canonical_name(name: str) -> str:
    """The unit's name as UNITS spells it ("uV/(m/s^2)" → "µV/(m/s²)", " mv/G " → "mV/g")."""
    text = name.strip().replace(" ", "")
    for ascii_text, proper in _ALIASES.items():
        text = text.replace(ascii_text, proper)
    for known in UNITS:
        if text.lower() == known.lower():
            return known
    return text


# Any "<prefix><V|C>/<acceleration unit>" a certificate may write (pC/(km/s²), nV/g …), parsed
# by hand: the few units a shock accelerometer's sensitivity is stated in need no units library.
PREFIXES = {"f": 1e-15, "p": 1e-12, "n": 1e-9, "µ": 1e-6, "μ": 1e-6, "u": 1e-6, "m": 1e-3, "": 1.0, "k": 1e3}
PER = {"m/s²": 1.0, "m/s^2": 1.0, "m/s2": 1.0, "(m/s²)": 1.0, "(m/s^2)": 1.0, "(m/s2)": 1.0, "ms^-2": 1.0,
       "g": G_M_S2, "g_n": G_M_S2, "gn": G_M_S2, "km/s²": 1e3, "(km/s²)": 1e3, "km/s^2": 1e3, "(km/s^2)": 1e3}
_UNIT = re.compile(r"^\s*([fpnµμumk]?)(V|C)\s*/\s*(.+?)\s*$")


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


def sensitivity_unit(name: str) -> SensitivityUnit:
    """The unit called `name` (ASCII spellings accepted; any unit `parse` reads beyond the
    offered UNITS); ValueError naming the offered ones."""
    found = UNITS.get(canonical_name(name))
    if found is not None:
        return found
    parsed = parse(name)
    if parsed is None:
        raise ValueError(f"sensitivity unit {name!r} is not known; use one of {', '.join(UNITS)}")
    prefix, kind, per = parsed
    return SensitivityUnit(name.strip(), kind, prefix / per)


def check_plausible(value: float, unit: SensitivityUnit) -> None:
    """ValueError, naming the unit and the plausible range in it, unless `value` is a plausible
    sensitivity (module docstring)."""
    low, high = unit.plausible_range()
    if not (isinstance(value, int | float) and math.isfinite(value) and low <= value <= high):
        raise ValueError(f"sensitivity {value:g} {unit.name} is outside the plausible range "
                         f"{low:.6g} … {high:.6g} {unit.name}: check the value and its unit")


def format_sensitivity(value_si: float, unit: SensitivityUnit, expanded_si: float | None = None) -> str:
    """'0.1966 µV/(m/s²)' or, with its U, '0.1966 ± 0.0017 µV/(m/s²)' (U to two significant digits)."""
    value = unit.from_si(value_si)
    if expanded_si is None or not (expanded_si > 0 and math.isfinite(expanded_si)):
        return f"{value:.4g} {unit.name}"
    big = unit.from_si(expanded_si)
    decimals = int(min(12, max(0, 1 - math.floor(math.log10(big)))))
    return f"{value:.{decimals}f} ± {big:.{decimals}f} {unit.name}"


# Response units in which the analysis already divided the response by the nominal sensitivity:
# the model's DC gain is then the sensitivity relative to nominal (1 = on nominal).
RATIO_UNITS = ("m/s^2",)


@dataclass(frozen=True)
class AbsoluteSensitivity:
    """A measured sensitivity in the sensor's own unit, with its U (95 %) and its ratio to the
    nominal sensitivity the shot was analysed with (None when the shot had no nominal)."""

    value_si: float  # input units per m/s²
    expanded_si: float | None
    unit: SensitivityUnit
    ratio: float | None  # measured ÷ nominal
    ratio_expanded: float | None

    def text(self) -> str:
        """'0.1955 ± 0.0016 µV/(m/s²)'."""
        return format_sensitivity(self.value_si, self.unit, self.expanded_si)

    @property
    def deviation_percent(self) -> float | None:
        """100·(measured ÷ nominal − 1); None without a nominal."""
        return None if self.ratio is None else 100.0 * (self.ratio - 1.0)

    def ratio_text(self) -> str:
        """'0.978× nominal (−2.2 %)' ("" without a nominal)."""
        if self.ratio is None or self.deviation_percent is None:
            return ""
        return f"{self.ratio:.3f}× nominal ({self.deviation_percent:+.1f} %)".replace("-", "−")


def absolute_sensitivity(value: float | None, expanded: float | None, response_unit: str,
                         nominal_si: float | None, unit: SensitivityUnit) -> AbsoluteSensitivity | None:
    """The model's DC gain (`value`, its U `expanded`, in the analysis' response units per
    m/s²) as an absolute sensitivity in `unit`: × the nominal the response was divided by when
    the response is in m/s² (RATIO_UNITS), else (volts: gain and nominal 1) as it is. None when
    the value is unknown, or relative to a nominal that is not known."""
    if value is None or not math.isfinite(value):
        return None
    if response_unit in RATIO_UNITS:
        if nominal_si is None or not (nominal_si > 0 and math.isfinite(nominal_si)):
            return None
        return AbsoluteSensitivity(value * nominal_si, None if expanded is None else expanded * nominal_si, unit,
                                   value, expanded)
    return AbsoluteSensitivity(value, expanded, unit, None, None)
