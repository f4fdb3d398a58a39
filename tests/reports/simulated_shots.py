"""Simulated shots for the report tests: records from known accelerometer models (drivers/sim)
and the report's shot entries; `analysed_shots` analyses three of them with the shared shot
analysis (the `analyses` fixture of tests/reports/conftest.py, once per test run)."""

from __future__ import annotations

import numpy as np

from hopkinson.analysis.records import Record
from hopkinson.analysis.shot_analysis import AnalysisOptions, ShotAnalysis, analyse_record
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode, white_noise
from hopkinson.drivers.sim.shock import G_M_S2, half_sine_m_s2
from hopkinson.reports.data import ShotEntry

DT = 1e-6
SENSOR_A = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),))
SENSOR_B = AccelerometerTruth(modes=(Mode(40_000.0, 0.03),))


def simulated_record(truth: AccelerometerTruth, peak_g: float, seed: int) -> Record:
    """A 2 ms record at 1 MS/s: half-sine pulse (38.6 µs) and the sensor's response, 50 dB SNR."""
    rng = np.random.default_rng(seed)
    t = np.arange(-200, 1800) * DT
    ref = half_sine_m_s2(t, 38.6e-6, peak_g * G_M_S2)
    resp = truth.respond(ref, DT)
    return Record(DT, ref + white_noise(ref, 50, rng), resp + white_noise(resp, 50, rng), t[0])


def entry(label: str, analysis: ShotAnalysis | None, truth: AccelerometerTruth | None = None,
          error: str | None = None, results: dict | None = None) -> ShotEntry:
    modes = None if truth is None else [{"natural_frequency_hz": m.natural_frequency_hz,
                                         "damping_ratio": m.damping_ratio} for m in truth.modes]
    return ShotEntry(label, {"Accelerometer": "SIM-ACC, serial T1", "Fired (UTC)": "2026-01-01T00:00:00Z"},
                     analysis, error=error, state="ANALYSED" if analysis else "ANALYSIS_FAILED",
                     truth_modes=modes, nominal_sensitivity_v_per_m_s2=2e-7, pressure_bar=2.0, results=results)


def analysed_shots() -> dict[str, ShotAnalysis]:
    """Two shots of SENSOR_A (30 000 g, 80 000 g) and one of SENSOR_B (50 000 g), analysed."""
    params = AnalysisOptions(max_order=6, draws=50, seed=1)  # the uncertainty with the fewest draws allowed
    return {
        "a1": analyse_record(simulated_record(SENSOR_A, 30_000, 1), params),
        "a2": analyse_record(simulated_record(SENSOR_A, 80_000, 2), params),
        "b1": analyse_record(simulated_record(SENSOR_B, 50_000, 3), params),
    }
