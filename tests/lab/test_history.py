"""A sensor's history judged: a calibration is a campaign; E_n between the newest and the
previous calibration at like levels against its closed form, the decision rules' verdicts, the
due date, simulated calibrations left out — on hand-computed cases."""

from __future__ import annotations

import math
from datetime import date

import pytest
from scipy.stats import t as student_t

from hopkinson.lab.history import calibrations_of, conformity_of, sensor_history
from hopkinson.lab.repositories import SensorInfo, ShotResult
from tests.lab.records import figure


def shot(utc: str, sensitivity: float, u: float, campaign: str = "run", peak: float = 4.9e5,
         simulated: bool = False, unit: str = "m/s^2") -> ShotResult:
    return ShotResult(utc, f"uuid-{utc}-{peak}", "shot", f"uuid-{campaign}", campaign, "HB-1", "tech", peak, 40e-6,
                      unit, {"sensitivity": figure(sensitivity, u)}, ("simulator's truth",) if simulated else ())


def history_of(shots: list[ShotResult], **kw):
    return sensor_history(SENSOR, calibrations_of(shots), **kw)


SENSOR = SensorInfo("SN-7", "ACC-20k", "ACME", None, "", 2.0, 30)


def test_drift_is_the_newest_calibration_against_the_previous_one_at_like_levels() -> None:
    # three campaigns; the newest (2026) has a level the previous one lacks (1.5 MN): it is left out
    shots = [shot("2025-01-01T00:00:00Z", 0.990, 0.001, "a"),
             shot("2025-06-01T00:00:00Z", 1.000, 0.001, "b"), shot("2025-06-01T00:01:00Z", 1.004, 0.001, "b"),
             shot("2026-01-01T00:00:00Z", 1.010, 0.001, "c"),
             shot("2026-01-01T00:01:00Z", 1.100, 0.001, "c", peak=1.5e6)]
    history = history_of(shots, today=date(2026, 1, 2))
    assert [len(c.shots) for c in history.calibrations] == [1, 2, 2]
    # previous ("b") combined (GUM G.4): mean 1.002, s = 0.002828, u_c² = s²/2 + ū², ν = u_c⁴/((s²/2)²/1)
    s = math.sqrt(((1.000 - 1.002) ** 2 + (1.004 - 1.002) ** 2) / 1)
    u_c = math.sqrt(s * s / 2 + 0.001 ** 2)
    previous_expanded = student_t.ppf(0.975, u_c ** 4 / (s * s / 2) ** 2) * u_c
    newest_expanded = student_t.ppf(0.975, math.inf) * 0.001  # the one like-level shot: u expanded, ν = ∞
    expected = (1.010 - 1.002) / math.sqrt(newest_expanded ** 2 + previous_expanded ** 2)
    drift = history.drift["sensitivity"]
    assert drift.previous == pytest.approx(1.002) and drift.newest == pytest.approx(1.010) and drift.levels == 1
    assert drift.e_n == pytest.approx(expected, rel=1e-9)
    assert drift.drifted is (abs(expected) > 1)
    steady = history_of([shot("2025-01-01T00:00:00Z", 1.000, 0.001, "a"),
                         shot("2026-01-01T00:00:00Z", 1.001, 0.001, "b")], today=date(2026, 1, 2))
    # one shot each: its u expanded with k = 1.960 (ν = ∞)
    k = student_t.ppf(0.975, math.inf)
    assert steady.drift["sensitivity"].e_n == pytest.approx(0.001 / math.sqrt(2 * (k * 0.001) ** 2), rel=1e-9)
    assert not steady.flags


def test_a_simulated_calibration_is_shown_marked_and_not_judged_unless_asked() -> None:
    shots = [shot("2025-01-01T00:00:00Z", 1.000, 0.001, "a"),
             shot("2026-01-01T00:00:00Z", 1.030, 0.001, "rehearsal", simulated=True)]
    history = history_of(shots, today=date(2026, 1, 2))
    assert [c.simulated for c in history.calibrations] == [False, True]
    assert "sensitivity" not in history.drift  # one real calibration: nothing to compare
    assert history.conformity.verdict == "pass"  # the real one, 0 %, not the rehearsal's +3 %
    assert history.due == date(2025, 1, 31)  # due from the real calibration
    assert "1 simulated calibration(s) not judged" in history.flags
    judged = history_of(shots, today=date(2026, 1, 2), include_simulated=True)
    assert judged.drift["sensitivity"].drifted and judged.conformity.verdict == "fail"
    assert history.to_dict()["calibrations"][1]["simulated_marks"] == ["simulator's truth"]


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
    history = history_of([shot("2026-01-01T08:00:00Z", 1.0, 0.001)], today=date(2026, 3, 1))
    assert history.due == date(2026, 1, 31) and history.overdue
    assert history.flags == ["overdue since 2026-01-31"]
    assert not history_of([shot("2026-01-01T08:00:00Z", 1.0, 0.001)], today=date(2026, 1, 31)).overdue


def test_the_stated_sensitivity_in_the_sensors_own_unit() -> None:
    """A ratio to the nominal the rig scaled by, times that nominal (V/(m/s²) at the
    conditioner's input), in the sensor's unit: 1.01 × 2e-7 V/(m/s²) = 1.981e-3 mV/g."""
    from dataclasses import replace

    shots = [replace(shot("2026-01-01T00:00:00Z", 1.01, 0.001), context={"sensitivity_v_per_m_s2": 2e-7})]
    sensor = SensorInfo("SN-7", "", "", 2e-3, "mV/g", 2.0, None)
    (c,) = calibrations_of(shots, sensor)
    assert c.absolute_unit == "mV/g"
    assert c.absolute.value == pytest.approx(1.01 * 2e-7 * 1e3 * 9.80665, rel=1e-12)
    assert c.absolute.expanded == pytest.approx(student_t.ppf(0.975, math.inf) * 0.001 * 2e-7 * 1e3 * 9.80665)
    (raw,) = calibrations_of([replace(shots[0], context={})], sensor)
    assert raw.absolute is None  # no scale recorded: never a guess


def test_drift_compares_absolute_sensitivities_not_ratios_to_two_nominals() -> None:
    """One sensor fired with nominal 0.312 and then 0.200 µV/(m/s²): the ratios (0.627, 0.9785)
    differ by 56 %, the sensitivities (0.19562, 0.19570 µV/(m/s²)) by 0.04 %; E_n compares
    the sensitivities: the closed form on V/(m/s²)."""
    from dataclasses import replace

    first = replace(shot("2025-01-01T00:00:00Z", 0.627, 0.002, "a"), context={"sensitivity_v_per_m_s2": 0.312e-6})
    second = replace(shot("2026-01-01T00:00:00Z", 0.9785, 0.002, "b"), context={"sensitivity_v_per_m_s2": 0.200e-6})
    drift = history_of([first, second], today=date(2026, 1, 2)).drift["sensitivity"]
    k = student_t.ppf(0.975, math.inf)
    a1, a2 = 0.627 * 0.312e-6, 0.9785 * 0.200e-6
    expected = (a2 - a1) / math.sqrt((k * 0.002 * 0.200e-6) ** 2 + (k * 0.002 * 0.312e-6) ** 2)
    assert drift.unit == "V/(m/s²)" and drift.newest == pytest.approx(a2, rel=1e-12)
    assert drift.e_n == pytest.approx(expected, rel=1e-9) and not drift.drifted
    # one scale not recorded and the other shot's nominal differs: the ratios are not compared at all
    unknown = replace(second, context={})
    assert "sensitivity" not in history_of([first, unknown], today=date(2026, 1, 2)).drift
