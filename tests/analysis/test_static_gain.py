"""analysis.static_gain: a shot's quasi-static gain at the amplitude it is measured at, against a
sensor of known sensitivity simulated here (not by the analysis):

- a linear sensor whose tension gain is 2 % below its compression gain (a bonded mount): the gain
  in the main pulse's direction is the compression sensitivity, the other direction's the tension
  one, each within its U;
- a sensor driven by a·(1 + c·|a|) (a Hammerstein input non-linearity, c known) on bipolar pulses
  at two levels: each shot's gain is S₀(1 + c·a_s) at the amplitude a_s it names (within U, U
  covering also what a single pulse's fitted dynamics take up), so two levels give c.
"""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.records import Record
from hopkinson.analysis.shot_analysis import analyse_record
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.shock import bipolar_m_s2

DT = 1e-7  # simulated at 10 MS/s, analysed at 1 MS/s
SENSITIVITY = 2.5
TENSION_LOSS = 0.02
TRUTH = AccelerometerTruth(modes=(Mode(30_000.0, 0.03),), sensitivity=SENSITIVITY)


def _record(peak_m_s2: float, nonlinearity_per_m_s2: float, seed: int) -> Record:
    rng = np.random.default_rng(seed)
    t = np.arange(20_000) * DT
    a = bipolar_m_s2(t, 40e-6, peak_m_s2, 300e-6, ratio=0.8)
    driven = a * (1.0 + nonlinearity_per_m_s2 * np.abs(a)) * np.where(a < 0, 1.0 - TENSION_LOSS, 1.0)
    y = TRUTH.respond(driven, DT)
    u = a + 0.003 * peak_m_s2 * rng.standard_normal(t.size)
    y = y + 0.003 * float(np.max(np.abs(y))) * rng.standard_normal(t.size)
    return Record(DT, u, y)


def _static(record: Record) -> dict:
    result = analyse_record(record, AnalysisOptions(max_order=4, draws=50, seed=3))
    static = result.to_dict()["static_gain"]
    assert "value" in static, static
    return static


def test_a_linear_sensor_reads_its_sensitivity_in_each_direction() -> None:
    static = _static(_record(3e5, 0.0, seed=1))
    big_u = 1.96 * static["u"]
    assert abs(static["value"] - SENSITIVITY) <= big_u, static
    assert static["other_direction"] == pytest.approx(SENSITIVITY * (1 - TENSION_LOSS), abs=max(big_u, 1e-3 * SENSITIVITY))
    assert 0.5 * 3e5 < static["amplitude_m_s2"] < 3e5  # an amplitude within the main lobe's
    assert big_u < 0.005 * SENSITIVITY  # and a useful one


def test_a_non_linear_sensor_reads_its_gain_at_the_amplitude_it_names() -> None:
    c = -1.0e-7  # −1 % per 100 km/s²
    low, high = (_static(_record(peak, c, seed=2)) for peak in (1.5e5, 6e5))
    for static in (low, high):
        expected = SENSITIVITY * (1 + c * static["amplitude_m_s2"])
        assert abs(static["value"] - expected) <= 1.96 * static["u"], (static, expected)
    slope = (high["value"] / low["value"] - 1) / (high["amplitude_m_s2"] - low["amplitude_m_s2"])
    assert slope == pytest.approx(c, rel=0.05)  # −0.98e-7 when written
