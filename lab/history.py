"""A sensor's calibrations judged over time: drift (E_n), tolerance and due date.

Drift. The newest calibration's value x is compared with the mean x̄ of the earlier ones,
combined as in a campaign (reports.statistics.combine: repeatability and the shots' own
uncertainties, expanded for 95 %): E_n = (x − x̄) / √(U_x² + U_x̄²) (ISO 13528 / ISO/IEC 17043).
|E_n| ≤ 1: consistent with the history; |E_n| > 1: drifted.

Tolerance. The newest sensitivity's deviation from nominal, against the sensor's tolerance,
judged by a decision rule (ILAC-G8:2019): "simple" acceptance (w = 0: pass when the measured
deviation lies within the tolerance) or "guarded" acceptance (w = U: pass when the deviation
plus U lies within it, fail when the deviation minus U lies outside, else a conditional
statement).

Due. The newest calibration's date plus the sensor's calibration interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, date, datetime, timedelta
from typing import Any

from hopkinson.analysis.key_figures import Figure
from hopkinson.lab.repository import Calibration, SensorInfo
from hopkinson.lab.schema import FIGURE_KEYS

DECISION_RULES = {
    "simple": "ILAC-G8:2019 simple acceptance (binary, guard band w = 0): pass when the measured deviation "
              "lies within the tolerance",
    "guarded": "ILAC-G8:2019 guarded acceptance (guard band w = U, 95 %): pass when the deviation plus U lies "
               "within the tolerance, fail when the deviation minus U lies outside it, otherwise conditional",
}
# Units in which the response was already divided by the nominal sensitivity the rig used:
# the sensitivity is then a ratio to nominal (1 = on nominal).
RATIO_UNITS = ("m/s^2",)


@dataclass(frozen=True)
class Drift:
    key: str
    newest: float
    newest_expanded: float | None
    history_mean: float
    history_expanded: float | None
    history_n: int
    e_n: float | None

    @property
    def drifted(self) -> bool:
        return self.e_n is not None and abs(self.e_n) > 1.0

    def to_dict(self) -> dict[str, Any]:
        return {"newest": self.newest, "newest_U": self.newest_expanded, "history_mean": self.history_mean,
                "history_U": self.history_expanded, "history_n": self.history_n, "E_n": self.e_n,
                "drifted": self.drifted}


@dataclass(frozen=True)
class Conformity:
    """A sensitivity judged against the tolerance (module doc)."""

    deviation_percent: float
    expanded_percent: float | None
    tolerance_percent: float
    rule: str
    verdict: str  # "pass", "fail", "conditional pass", "conditional fail"

    def statement(self) -> str:
        u = f" (U = {self.expanded_percent:.2f} %, k ≈ 2)" if self.expanded_percent is not None else ""
        return (f"{self.verdict.upper()}: sensitivity deviates {self.deviation_percent:+.2f} %{u} from nominal; "
                f"tolerance ±{self.tolerance_percent:g} %; decision rule: {DECISION_RULES[self.rule]}")


@dataclass(frozen=True)
class SensorHistory:
    sensor: SensorInfo
    calibrations: list[Calibration]
    drift: dict[str, Drift] = field(default_factory=dict)
    conformity: Conformity | None = None
    due: date | None = None
    overdue: bool = False

    @property
    def flags(self) -> list[str]:
        out = [f"drift in {d.key} (E_n = {d.e_n:+.2f})" for d in self.drift.values() if d.drifted]
        if self.conformity is not None and self.conformity.verdict != "pass":
            out.append(f"out of tolerance: {self.conformity.verdict}")
        if self.overdue:
            out.append(f"overdue since {self.due.isoformat()}")
        return out

    def to_dict(self) -> dict[str, Any]:
        s = self.sensor
        return {
            "sensor": {"serial": s.serial, "model": s.model, "owner": s.owner,
                       "nominal_sensitivity": s.nominal_sensitivity, "sensitivity_unit": s.sensitivity_unit,
                       "tolerance_percent": s.tolerance_percent, "interval_days": s.interval_days},
            "calibrations": [
                {"utc_time": c.utc_time, "shot_uuid": c.shot_uuid, "shot": c.shot_name, "campaign": c.campaign,
                 "rig": c.rig, "operator": c.operator, "response_unit": c.response_unit,
                 "peak_acceleration_m_s2": c.peak_acceleration_m_s2,
                 "figures": {k: _figure_dict(f) for k, f in c.figures.items()}}
                for c in self.calibrations],
            "drift": {k: d.to_dict() for k, d in self.drift.items()},
            "conformity": None if self.conformity is None else {
                "deviation_percent": self.conformity.deviation_percent,
                "expanded_percent": self.conformity.expanded_percent,
                "tolerance_percent": self.conformity.tolerance_percent, "rule": self.conformity.rule,
                "verdict": self.conformity.verdict, "statement": self.conformity.statement()},
            "due": self.due.isoformat() if self.due else None,
            "overdue": self.overdue,
            "flags": self.flags,
        }


def _figure_dict(figure: Figure | None) -> dict[str, Any] | None:
    if figure is None:
        return None
    return dict(figure.to_dict(), U=figure.expanded)


def drift_of(key: str, calibrations: list[Calibration]) -> Drift | None:
    """The newest value of `key` against the earlier ones (module doc); None without both."""
    from hopkinson.reports.statistics import combine

    known = [c.figures.get(key) for c in calibrations if c.figures.get(key) is not None]
    if len(known) < 2:
        return None
    newest, earlier = known[-1], known[:-1]
    history = combine(earlier)
    if history.mean is None:
        return None
    u_new, u_hist = newest.expanded, history.expanded
    variance = (u_new or 0.0) ** 2 + (u_hist or 0.0) ** 2
    e_n = (newest.value - history.mean) / math.sqrt(variance) if variance > 0 else None
    return Drift(key, newest.value, u_new, history.mean, u_hist, history.n, e_n)


def conformity_of(sensitivity: Figure, response_unit: str, sensor: SensorInfo, rule: str) -> Conformity | None:
    """The sensitivity against the sensor's tolerance (None when no tolerance or nominal is known)."""
    if rule not in DECISION_RULES:
        raise ValueError(f"decision rule {rule!r}: one of {', '.join(DECISION_RULES)}")
    if sensor.tolerance_percent is None or sensitivity.value is None:
        return None
    if response_unit in RATIO_UNITS:
        nominal = 1.0
    elif sensor.nominal_sensitivity:
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
    return Conformity(deviation, expanded, tol, rule, verdict)


def sensor_history(sensor: SensorInfo, calibrations: list[Calibration], rule: str = "simple",
                   today: date | None = None) -> SensorHistory:
    """Judge a sensor's calibrations (module doc)."""
    drift = {}
    for key in FIGURE_KEYS:
        d = drift_of(key, calibrations)
        if d is not None:
            drift[key] = d
    conformity = due = None
    overdue = False
    if calibrations:
        newest = calibrations[-1]
        sensitivity = newest.figures.get("sensitivity")
        if sensitivity is not None:
            conformity = conformity_of(sensitivity, newest.response_unit, sensor, rule)
        if sensor.interval_days:
            last = datetime.fromisoformat(newest.utc_time.replace("Z", "+00:00")).date()
            due = last + timedelta(days=sensor.interval_days)
            overdue = (today or datetime.now(UTC).date()) > due
    return SensorHistory(sensor, calibrations, drift, conformity, due, overdue)
