"""A sensor's history judged: E_n against its closed form, the decision rules' verdicts, the
due date — on hand-computed cases."""

from __future__ import annotations

import math
from datetime import date

import pytest
from hopkinson.lab.history import conformity_of, sensor_history
from hopkinson.lab.repository import Calibration, SensorInfo
from scipy.stats import t as student_t

from tests.lab.records import figure


def calibration(utc: str, sensitivity: float, u: float, unit: str = "m/s^2") -> Calibration:
    return Calibration(utc, "uuid", "shot", "run", "HB-1", "tech", 4.9e5, unit, {"sensitivity": figure(sensitivity, u)})


SENSOR = SensorInfo("SN-7", "ACC-20k", "ACME", None, "", 2.0, 30)


def test_drift_is_the_newest_against_the_earlier_ones_with_their_combined_uncertainty() -> None:
    history = sensor_history(SENSOR, [calibration("2025-01-01T00:00:00Z", 1.000, 0.001),
                                      calibration("2025-06-01T00:00:00Z", 1.002, 0.001),
                                      calibration("2026-01-01T00:00:00Z", 1.010, 0.001)], today=date(2026, 1, 2))
    # the earlier two combined (GUM G.4): mean 1.001, u_c² = s²/n + ū² = 1e-6 + 1e-6, ν = 4
    u_c = math.sqrt(2e-6)
    expanded_history = student_t.ppf(0.975, 4) * u_c
    expected = (1.010 - 1.001) / math.sqrt(0.002 ** 2 + expanded_history ** 2)
    drift = history.drift["sensitivity"]
    assert drift.history_mean == pytest.approx(1.001) and drift.history_n == 2
    assert drift.e_n == pytest.approx(expected, rel=1e-9)
    assert drift.drifted and expected > 1
    assert history.flags == [f"drift in sensitivity (E_n = {expected:+.2f})"]
    steady = sensor_history(SENSOR, [calibration("2025-01-01T00:00:00Z", 1.000, 0.001),
                                     calibration("2026-01-01T00:00:00Z", 1.001, 0.001)], today=date(2026, 1, 2))
    # one earlier shot: its u expanded with k = 1.960 (ν = ∞); the newest's U is its interval's half-width
    expected = 0.001 / math.sqrt(0.002 ** 2 + (student_t.ppf(0.975, math.inf) * 0.001) ** 2)
    assert steady.drift["sensitivity"].e_n == pytest.approx(expected, rel=1e-9)
    assert not steady.flags


@pytest.mark.parametrize(("deviation", "u_rel", "rule", "verdict"), [
    (1.5, 0.4, "simple", "pass"),
    (2.5, 0.4, "simple", "fail"),
    (1.5, 0.4, "guarded", "conditional pass"),  # 1.5 + 0.8 > 2 ≥ 1.5
    (1.0, 0.4, "guarded", "pass"),  # 1.0 + 0.8 ≤ 2
    (2.2, 0.4, "guarded", "conditional fail"),  # 2.2 − 0.8 ≤ 2 < 2.2
    (3.0, 0.4, "guarded", "fail"),  # 3.0 − 0.8 > 2
])
def test_decision_rules_give_ilac_g8_verdicts(deviation: float, u_rel: float, rule: str, verdict: str) -> None:
    nominal = 2.0e-7  # V per m/s², the response in volts
    sensor = SensorInfo("SN-7", "", "", nominal, "V/(m/s²)", 2.0, None)
    measured = figure(nominal * (1 + deviation / 100), nominal * u_rel / 100)  # U = 2u
    judged = conformity_of(measured, "V", sensor, rule)
    assert judged.verdict == verdict
    assert judged.deviation_percent == pytest.approx(deviation)
    assert judged.expanded_percent == pytest.approx(2 * u_rel)
    assert ("ILAC-G8" in judged.statement()) and (verdict.upper() in judged.statement())


def test_without_a_tolerance_there_is_no_statement_and_overdue_is_flagged() -> None:
    assert conformity_of(figure(1.0, 0.001), "m/s^2", SensorInfo("S", "", "", None, "", None, None), "simple") is None
    history = sensor_history(SENSOR, [calibration("2026-01-01T08:00:00Z", 1.0, 0.001)], today=date(2026, 3, 1))
    assert history.due == date(2026, 1, 31) and history.overdue
    assert history.flags == ["overdue since 2026-01-31"]
    assert not sensor_history(SENSOR, [calibration("2026-01-01T08:00:00Z", 1.0, 0.001)],
                              today=date(2026, 1, 31)).overdue
