"""Simulated shock records with a known truth and the hard parts of real ones (issue 10), for the
robustness suite and the coverage study: generated at 10 MS/s (the analysis resamples them to
1 MS/s, as a real record is), a half-sine or bipolar pulse, white or interferometer-like noise
on the reference, white noise on the response, a channel skew, a baseline drift, a record cut
short. The truth's figures are computed from the continuous model (FBSD) and the noise-free
record at 10 MS/s (peak ratio)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hopkinson.analysis.records import Record
from hopkinson.analysis.response import band_edges
from hopkinson.drivers.sim.accelerometer import (
    AccelerometerTruth,
    Mode,
    baseline_drift,
    fractional_delay,
)
from hopkinson.drivers.sim.doppler_beat import interferometer_noise_m_s2
from hopkinson.drivers.sim.shock import bipolar_m_s2, half_sine_m_s2

DT = 1e-7  # 10 MS/s
ANALYSIS_DT = 1e-6


@dataclass(frozen=True)
class Case:
    """One kind of record (noise levels relative to each channel's peak)."""

    truth: AccelerometerTruth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),), sensitivity=2.5)
    width_s: float = 20e-6
    bipolar_ratio: float = 0.0
    samples: int = 12_000  # at 10 MS/s
    start_s: float = 150e-6
    reference_noise: float = 0.01  # white, RMS / peak
    interferometer_noise: float = 0.0  # f² noise up to `interferometer_band_hz`, RMS / peak
    interferometer_band_hz: float = 400e3
    response_noise: float = 0.01
    skew_samples: float = 0.0  # response delayed by this many analysis samples (< 0: it leads)
    drift_per_s: float = 0.0  # response baseline drift, × peak per second
    cut_s: float | None = None  # record cut this long after its start

    def scaled(self, **changes: float) -> Case:
        return replace(self, **changes)


def record(case: Case, seed: int) -> Record:
    """The case's record for one noise seed."""
    rng = np.random.default_rng(seed)
    t = np.arange(case.samples) * DT
    u0 = bipolar_m_s2(t, case.width_s, 1.0, case.start_s, case.bipolar_ratio) if case.bipolar_ratio else \
        half_sine_m_s2(t, case.width_s, 1.0, case.start_s)
    y0 = case.truth.respond(u0, DT)
    peak_y = float(np.max(np.abs(y0)))
    u = u0 + case.reference_noise * rng.standard_normal(t.size)
    if case.interferometer_noise:
        u = u + interferometer_noise_m_s2(t.size, DT, case.interferometer_noise, case.interferometer_band_hz, rng)
    y = y0 + case.response_noise * peak_y * rng.standard_normal(t.size)
    if case.skew_samples:
        y = fractional_delay(y, case.skew_samples * ANALYSIS_DT / DT)
    if case.drift_per_s:
        y = y + baseline_drift(t.size, DT, case.drift_per_s * peak_y)
    if case.cut_s is not None:
        keep = int(round(case.cut_s / DT))
        u, y = u[:keep], y[:keep]
    return Record(DT, u, y)


def truth_figures(case: Case) -> dict[str, float]:
    """The figures the analysis estimates, from the truth."""
    truth = case.truth
    dc = abs(truth.frequency_response(np.array([0.0]))[0])
    edges = band_edges(lambda f: np.abs(truth.frequency_response(f)) / dc, 400e3)
    t = np.arange(case.samples) * DT
    u0 = bipolar_m_s2(t, case.width_s, 1.0, case.start_s, case.bipolar_ratio) if case.bipolar_ratio else \
        half_sine_m_s2(t, case.width_s, 1.0, case.start_s)
    y0 = truth.respond(u0, DT)
    return {
        "dc_gain": truth.sensitivity,
        "natural_frequency_hz": truth.modes[0].natural_frequency_hz,
        "damping_ratio": truth.modes[0].damping_ratio,
        "fbsd_5": edges["5"].frequency_hz,
        "fbsd_10": edges["10"].frequency_hz,
        "shock_sensitivity": float(y0[np.argmax(np.abs(y0))] / u0[np.argmax(np.abs(u0))]),
    }
