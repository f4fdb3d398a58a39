"""A sensor's calibrations judged over time. A calibration is a campaign: its shots combined
(reports.statistics.combine: repeatability and the shots' own uncertainties, expanded for
95 %), per level and over all. Lone shots (no campaign) each count as their own calibration.

Drift. The newest calibration against the one before, at like levels only (shots whose peak
accelerations lie within `LIKE_LEVEL_RATIO` of a level of the other calibration), so that
neither repeatability within a campaign nor a sensitivity's dependence on the level passes
for drift: E_n = (x − x_prev) / √(U_x² + U_prev²) (ISO 13528 / ISO/IEC 17043). |E_n| ≤ 1:
consistent; |E_n| > 1: drifted.

Tolerance. The newest calibration's stated sensitivity against the sensor's tolerance, judged
by a decision rule (ILAC-G8:2019): "simple" acceptance (w = 0) or "guarded" acceptance (w = U:
pass when the deviation plus U lies within it, fail when the deviation minus U lies outside,
else a conditional statement).

Due. The newest calibration's last day plus the sensor's calibration interval.

Simulated calibrations are shown, marked, and left out of drift, tolerance and due date
unless asked (`include_simulated`).

`load_sensor_history(db, serial, …)` is what the command line and the panel read:
`SensorHistory.calibrations` (oldest first), each a `Calibration` with `figures` (combined, in
the response's unit), `absolute` (the stated sensitivity in the sensor's own unit, when the
record knows the scale), `simulated`, `levels`; `drift`, `conformity`, `due`, `flags` and
`certificates` (each with the certificate that withdrew it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, date, datetime, timedelta
from typing import TYPE_CHECKING, Any

from hopkinson.analysis import sensitivity_units as units
from hopkinson.analysis.key_figures import Figure
from hopkinson.lab.errors import LabError
from hopkinson.lab.repositories import SensorInfo, ShotResult
from hopkinson.lab.schema import FIGURE_KEYS

if TYPE_CHECKING:
    from hopkinson.lab.uow import LabDatabase

DECISION_RULES = {
    "simple": "ILAC-G8:2019 simple acceptance (binary, guard band w = 0): pass when the measured deviation "
              "lies within the tolerance",
    "guarded": "ILAC-G8:2019 guarded acceptance (guard band w = U, 95 %): pass when the deviation plus U lies "
               "within the tolerance, fail when the deviation minus U lies outside it, otherwise conditional",
}
# Units in which the response was already divided by the nominal sensitivity the rig used:
# the sensitivity is then a ratio to nominal (1 = on nominal).
RATIO_UNITS = ("m/s^2",)
LEVEL_SPREAD = 1.15  # shots within 15 % of a level's lowest peak belong to that level
LIKE_LEVEL_RATIO = 1.25  # two levels are alike when their peaks differ by less than 25 %


@dataclass(frozen=True)
class Level:
    """The shots of one calibration at one shock level, combined."""

    peak_m_s2: float  # mean peak acceleration
    pulse_width_s: float | None  # mean pulse duration
    shots: tuple[ShotResult, ...]

    def combined(self, key: str) -> Figure | None:
        return combined_figure([s.figures.get(key) for s in self.shots])


@dataclass(frozen=True)
class Calibration:
    """One calibration: a campaign's analysed shots (module doc)."""

    campaign_uuid: str
    campaign: str
    shots: tuple[ShotResult, ...]
    absolute: Figure | None = None  # the stated sensitivity in `absolute_unit` (None: scale unknown)
    absolute_unit: str = ""

    @property
    def utc_time(self) -> str:
        return self.shots[-1].utc_time

    @property
    def first_utc(self) -> str:
        return self.shots[0].utc_time

    @property
    def rig(self) -> str:
        return ", ".join(sorted({s.rig for s in self.shots}))

    @property
    def operator(self) -> str:
        return ", ".join(sorted({s.operator for s in self.shots if s.operator}))

    @property
    def response_unit(self) -> str:
        return self.shots[-1].response_unit

    @property
    def simulated(self) -> bool:
        return any(s.simulated for s in self.shots)

    @property
    def simulated_marks(self) -> tuple[str, ...]:
        return tuple(sorted({m for s in self.shots for m in s.simulated_marks}))

    @property
    def figures(self) -> dict[str, Figure | None]:
        """Every key figure combined over the calibration's shots."""
        return {key: combined_figure([s.figures.get(key) for s in self.shots]) for key in FIGURE_KEYS}

    @property
    def levels(self) -> tuple[Level, ...]:
        return levels_of(self.shots)


def combined_figure(figures: list[Figure | None]) -> Figure | None:
    """The shots' figures combined (reports.statistics.combine); None when none is known; a
    figure without U when the shots carry no uncertainty."""
    from hopkinson.reports.statistics import combine

    combined = combine(figures)
    if combined.mean is None:
        return None
    return combined.figure() if combined.expanded else Figure(combined.mean)


def levels_of(shots: tuple[ShotResult, ...] | list[ShotResult]) -> tuple[Level, ...]:
    """The shots grouped by peak acceleration (LEVEL_SPREAD), lowest first; shots without a
    peak form no level."""
    known = sorted((s for s in shots if s.peak_acceleration_m_s2), key=lambda s: s.peak_acceleration_m_s2)
    groups: list[list[ShotResult]] = []
    for s in known:
        if groups and s.peak_acceleration_m_s2 <= groups[-1][0].peak_acceleration_m_s2 * LEVEL_SPREAD:
            groups[-1].append(s)
        else:
            groups.append([s])
    out = []
    for g in groups:
        widths = [s.pulse_width_s for s in g if s.pulse_width_s]
        out.append(Level(sum(s.peak_acceleration_m_s2 for s in g) / len(g),
                         sum(widths) / len(widths) if widths else None, tuple(g)))
    return tuple(out)


def calibrations_of(results: list[ShotResult], sensor: SensorInfo | None = None) -> list[Calibration]:
    """The shots grouped into calibrations (a campaign each; a lone shot its own), oldest first."""
    groups: dict[str, list[ShotResult]] = {}
    for r in results:
        groups.setdefault(r.campaign_uuid or f"shot:{r.shot_uuid}", []).append(r)
    out = []
    for key, shots in groups.items():
        absolute, unit = absolute_sensitivity(shots, sensor)
        out.append(Calibration("" if key.startswith("shot:") else key, shots[0].campaign, tuple(shots),
                               absolute, unit))
    return sorted(out, key=lambda c: (c.utc_time, c.campaign_uuid))


def absolute_sensitivity(shots: list[ShotResult], sensor: SensorInfo | None) -> tuple[Figure | None, str]:
    """The stated sensitivity in the sensor's unit (else V, mV or µV per m/s² at the conditioner's input),
    from each shot's figure and the scale its response was divided by; (None, "") when a shot's
    scale is not recorded."""
    scaled = _absolute_figures("sensitivity", shots)
    if scaled is None:
        return None, ""
    base = combined_figure(scaled) if any(f is not None for f in scaled) else None
    if base is None:
        return None, ""
    wanted = sensor.sensitivity_unit if sensor and sensor.sensitivity_unit else ""
    k = units.factor("V/(m/s²)", wanted) if wanted else None
    if k is None:  # no unit recorded for the sensor (or not convertible): a readable prefix
        prefixes = ((1.0, "V/(m/s²)"), (1e3, "mV/(m/s²)"), (1e6, "µV/(m/s²)"))
        scale, shown = next((p for p in prefixes if abs(base.value or 0.0) * p[0] >= 0.1), prefixes[-1])
        return _scaled(base, scale), shown
    return _scaled(base, k), wanted


def _input_scale(shot: ShotResult) -> float | None:
    """Conditioner-input volts per m/s² that one unit of the shot's sensitivity stands for."""
    ctx = shot.context
    if shot.response_unit in RATIO_UNITS:
        value = ctx.get("sensitivity_v_per_m_s2")
    elif shot.response_unit == "V":
        gain = ctx.get("amplifier_gain")
        value = 1.0 / gain if gain else None
    else:
        value = None
    return float(value) if isinstance(value, int | float) and value else None


def _scaled(figure: Figure, k: float) -> Figure:
    return Figure(figure.value * k if figure.value is not None else None,
                  figure.u * abs(k) if figure.u is not None else None,
                  (figure.interval[0] * k, figure.interval[1] * k) if figure.interval else None)


@dataclass(frozen=True)
class Drift:
    key: str
    newest: float
    newest_expanded: float | None
    previous: float
    previous_expanded: float | None
    levels: int  # how many like levels were compared
    e_n: float | None
    unit: str = ""  # "V/(m/s²)": a sensitivity compared as an absolute value; "": as stated

    @property
    def drifted(self) -> bool:
        return self.e_n is not None and abs(self.e_n) > 1.0

    def to_dict(self) -> dict[str, Any]:
        return {"newest": self.newest, "newest_U": self.newest_expanded, "previous": self.previous,
                "previous_U": self.previous_expanded, "like_levels": self.levels, "E_n": self.e_n,
                "drifted": self.drifted, "unit": self.unit}


def like_shots(newest: Calibration, previous: Calibration) -> tuple[list[ShotResult], list[ShotResult], int]:
    """The shots of each calibration at the levels both share (LIKE_LEVEL_RATIO); all shots of
    both when neither knows its levels."""
    a_levels, b_levels = newest.levels, previous.levels
    if not a_levels and not b_levels:
        return list(newest.shots), list(previous.shots), 0
    a_out: list[ShotResult] = []
    b_out: list[ShotResult] = []
    pairs = 0
    for a in a_levels:
        alike = [b for b in b_levels if max(a.peak_m_s2, b.peak_m_s2) / min(a.peak_m_s2, b.peak_m_s2)
                 < LIKE_LEVEL_RATIO]
        if alike:
            pairs += 1
            a_out.extend(a.shots)
            for b in alike:
                b_out.extend(s for s in b.shots if s not in b_out)
    return a_out, b_out, pairs


def drift_of(key: str, calibrations: list[Calibration]) -> Drift | None:
    """The newest calibration's `key` against the previous one's at like levels (module doc). A
    sensitivity is compared as an absolute value: the same sensor fired with two nominals gives
    two ratios but one sensitivity."""
    if len(calibrations) < 2:
        return None
    newest_shots, previous_shots, pairs = like_shots(calibrations[-1], calibrations[-2])
    unit = ""
    newest_figures, previous_figures = _stated_figures(key, newest_shots), _stated_figures(key, previous_shots)
    if key in SENSITIVITY_KEYS:
        newest_abs, previous_abs = _absolute_figures(key, newest_shots), _absolute_figures(key, previous_shots)
        if newest_abs is not None and previous_abs is not None:
            newest_figures, previous_figures, unit = newest_abs, previous_abs, "V/(m/s²)"
        elif len({_input_scale(s) for s in (*newest_shots, *previous_shots)}) != 1:
            return None  # a scale not recorded, and ratios to different nominals: not comparable
    newest = combined_figure(newest_figures)
    previous = combined_figure(previous_figures)
    if newest is None or previous is None or newest.value is None or previous.value is None:
        return None
    variance = (newest.expanded or 0.0) ** 2 + (previous.expanded or 0.0) ** 2
    e_n = (newest.value - previous.value) / math.sqrt(variance) if variance > 0 else None
    return Drift(key, newest.value, newest.expanded, previous.value, previous.expanded, pairs, e_n, unit)


SENSITIVITY_KEYS = ("sensitivity", "shock_sensitivity")  # compared as absolute values (V/(m/s²))


def _stated_figures(key: str, shots: list[ShotResult]) -> list[Figure | None]:
    return [s.figures.get(key) for s in shots]


def _absolute_figures(key: str, shots: list[ShotResult]) -> list[Figure | None] | None:
    """Each shot's `key` in V/(m/s²) at the conditioner's input (None: a shot's scale is not
    recorded): the same sensor fired with two nominals gives two ratios but one sensitivity."""
    out: list[Figure | None] = []
    for s in shots:
        figure = s.figures.get(key)
        if figure is None or figure.value is None:
            out.append(None)
            continue
        scale = _input_scale(s)
        if scale is None:
            return None
        out.append(_scaled(figure, scale))
    return out


@dataclass(frozen=True)
class Conformity:
    """A sensitivity judged against the tolerance (module doc)."""

    deviation_percent: float
    expanded_percent: float | None
    tolerance_percent: float
    rule: str
    verdict: str  # "pass", "fail", "conditional pass", "conditional fail"
    quantity: str = "sensitivity"

    def statement(self) -> str:
        u = f" (U = {self.expanded_percent:.2f} %, k ≈ 2)" if self.expanded_percent is not None else ""
        return (f"{self.verdict.upper()}: {self.quantity} deviates {self.deviation_percent:+.2f} %{u} from nominal; "
                f"tolerance ±{self.tolerance_percent:g} %; decision rule: {DECISION_RULES[self.rule]}")


def conformity_of(sensitivity: Figure, response_unit: str, sensor: SensorInfo, rule: str,
                  quantity: str = "sensitivity") -> Conformity | None:
    """The sensitivity against the sensor's tolerance (None when no tolerance or nominal is known)."""
    if rule not in DECISION_RULES:
        raise ValueError(f"decision rule {rule!r}: one of {', '.join(DECISION_RULES)}")
    if sensor.tolerance_percent is None or sensitivity.value is None:
        return None
    if response_unit in RATIO_UNITS:
        nominal = 1.0
    elif sensor.nominal_sensitivity:  # `sensitivity` in the sensor's unit (the caller's scale)
        nominal = sensor.nominal_sensitivity
    else:
        return None
    deviation = 100.0 * (sensitivity.value / nominal - 1.0)
    expanded = 100.0 * sensitivity.expanded / abs(nominal) if sensitivity.expanded is not None else None
    tol = sensor.tolerance_percent
    w = expanded if rule == "guarded" and expanded is not None else 0.0
    if abs(deviation) + w <= tol:
        verdict = "pass"
    elif abs(deviation) - w > tol:
        verdict = "fail"
    else:
        verdict = "conditional pass" if abs(deviation) <= tol else "conditional fail"
    return Conformity(deviation, expanded, tol, rule, verdict, quantity)


def judge(calibration: Calibration, sensor: SensorInfo, rule: str) -> Conformity | None:
    """The calibration's stated sensitivity against the sensor's tolerance: as a ratio to the
    nominal the rig scaled by, else in the sensor's own unit (None when neither is known)."""
    ratio = calibration.figures.get("sensitivity")
    if ratio is not None and calibration.response_unit in RATIO_UNITS:
        return conformity_of(ratio, calibration.response_unit, sensor, rule)
    if calibration.absolute is not None and calibration.absolute_unit == sensor.sensitivity_unit:
        return conformity_of(calibration.absolute, calibration.absolute_unit, sensor, rule)
    return None


@dataclass(frozen=True)
class SensorHistory:
    sensor: SensorInfo
    calibrations: list[Calibration]
    drift: dict[str, Drift] = field(default_factory=dict)
    conformity: Conformity | None = None
    due: date | None = None
    overdue: bool = False
    include_simulated: bool = False
    certificates: list[dict[str, Any]] = field(default_factory=list)

    @property
    def judged(self) -> list[Calibration]:
        """The calibrations drift, tolerance and due date count (module doc)."""
        return [c for c in self.calibrations if self.include_simulated or not c.simulated]

    @property
    def flags(self) -> list[str]:
        out = [f"drift in {d.key} (E_n = {d.e_n:+.2f})" for d in self.drift.values() if d.drifted]
        if self.conformity is not None and self.conformity.verdict != "pass":
            out.append(f"out of tolerance: {self.conformity.verdict}")
        if self.overdue:
            out.append(f"overdue since {self.due.isoformat()}")
        simulated = len(self.calibrations) - len(self.judged) if not self.include_simulated else \
            sum(c.simulated for c in self.calibrations)
        if simulated:
            out.append(f"{simulated} simulated calibration(s) "
                       + ("included in the judgement" if self.include_simulated else "not judged"))
        return out

    def to_dict(self) -> dict[str, Any]:
        s = self.sensor
        return {
            "sensor": {"serial": s.serial, "model": s.model, "owner": s.owner,
                       "nominal_sensitivity": s.nominal_sensitivity, "sensitivity_unit": s.sensitivity_unit,
                       "tolerance_percent": s.tolerance_percent, "interval_days": s.interval_days},
            "calibrations": [calibration_dict(c) for c in self.calibrations],
            "drift": {k: d.to_dict() for k, d in self.drift.items()},
            "conformity": None if self.conformity is None else {
                "deviation_percent": self.conformity.deviation_percent,
                "expanded_percent": self.conformity.expanded_percent,
                "tolerance_percent": self.conformity.tolerance_percent, "rule": self.conformity.rule,
                "verdict": self.conformity.verdict, "statement": self.conformity.statement()},
            "due": self.due.isoformat() if self.due else None,
            "overdue": self.overdue,
            "include_simulated": self.include_simulated,
            "flags": self.flags,
            "certificates": self.certificates,
        }


def calibration_dict(c: Calibration) -> dict[str, Any]:
    return {"campaign_uuid": c.campaign_uuid, "campaign": c.campaign, "first_utc": c.first_utc,
            "utc_time": c.utc_time, "rig": c.rig, "operator": c.operator, "response_unit": c.response_unit,
            "simulated": c.simulated, "simulated_marks": list(c.simulated_marks),
            "absolute_sensitivity": _figure_dict(c.absolute), "absolute_unit": c.absolute_unit,
            "figures": {k: _figure_dict(f) for k, f in c.figures.items()},
            "levels": [{"peak_acceleration_m_s2": lv.peak_m_s2, "pulse_width_s": lv.pulse_width_s,
                        "shots": len(lv.shots), "sensitivity": _figure_dict(lv.combined("sensitivity"))}
                       for lv in c.levels],
            "shots": [{"utc_time": s.utc_time, "shot_uuid": s.shot_uuid, "shot": s.shot_name,
                       "peak_acceleration_m_s2": s.peak_acceleration_m_s2, "simulated": s.simulated,
                       "figures": {k: _figure_dict(f) for k, f in s.figures.items()}} for s in c.shots]}


def _figure_dict(figure: Figure | None) -> dict[str, Any] | None:
    if figure is None:
        return None
    return dict(figure.to_dict(), U=figure.expanded)


def sensor_history(sensor: SensorInfo, calibrations: list[Calibration], rule: str = "simple",
                   today: date | None = None, include_simulated: bool = False,
                   certificates: list[dict[str, Any]] | None = None) -> SensorHistory:
    """Judge a sensor's calibrations (module doc)."""
    history = SensorHistory(sensor, calibrations, include_simulated=include_simulated,
                            certificates=certificates or [])
    judged = history.judged
    drift = {key: d for key in FIGURE_KEYS if (d := drift_of(key, judged)) is not None}
    conformity = due = None
    overdue = False
    if judged:
        newest = judged[-1]
        conformity = judge(newest, sensor, rule)
        if sensor.interval_days:
            last = datetime.fromisoformat(newest.utc_time.replace("Z", "+00:00")).date()
            due = last + timedelta(days=sensor.interval_days)
            overdue = (today or datetime.now(UTC).date()) > due
    return SensorHistory(sensor, calibrations, drift, conformity, due, overdue, include_simulated,
                         certificates or [])


def load_sensor_history(db: LabDatabase, serial: str, rule: str = "simple", include_simulated: bool = False,
                        today: date | None = None) -> SensorHistory:
    """A sensor's judged history from the record (module doc); LabError when it is not there."""
    with db.reading() as uow:
        sensor = uow.sensors.info(serial)
        if sensor is None:
            raise LabError(f"sensor {serial.strip() or repr(serial)}: not in the lab's record")
        results = uow.shots.results(sensor.serial)
        certificates = uow.certificates.of_sensor(sensor.serial)
    return sensor_history(sensor, calibrations_of(results, sensor), rule, today, include_simulated, certificates)
