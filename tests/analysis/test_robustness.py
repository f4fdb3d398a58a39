"""Robustness suite (issue 10): rescaled channels, rising noise, delays of either sign, truncated
records and the other hard parts of real records. Each result is stable and within its
interval, or carries a warning that says why not. Truth: tests/analysis/hard_records.py."""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.analysis.identify import identify
from hopkinson.analysis.options import DEFAULT_DRAWS, AnalysisOptions
from hopkinson.analysis.records import Record
from hopkinson.analysis.response import fbsd_hz
from hopkinson.analysis.uncertainty import evaluate
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from tests.analysis.hard_records import Case, record, truth_figures

NO_CHAIN = dict(u_grating_pitch_rel=0.0, u_interferometer_rel=0.0, u_amp_gain_rel=0.0, u_digitizer_gain_rel=0.0,
                u_channel_skew_s=0.0)
BASE = Case()


# --- invariance to scale and units ----------------------------------------------------------------


@pytest.fixture(scope="module")
def nominal():
    rec = record(BASE.scaled(truth=AccelerometerTruth(modes=(Mode(27_000.0, 0.05),), lowpass_hz=90_000.0)), 11)
    return rec, identify(rec)


@pytest.mark.parametrize(("channel", "factor"), [("reference", 1.001), ("response", 1.02),
                                                 ("response", 1 / 9.80665), ("reference", 1e6), ("response", 1e-6)])
def test_rescaling_a_channel_changes_nothing_but_the_dc_gain(nominal, channel: str, factor: float) -> None:
    rec, base = nominal
    scaled = Record(rec.sample_interval_s, rec.reference * (factor if channel == "reference" else 1.0),
                    rec.response * (factor if channel == "response" else 1.0))
    result = identify(scaled)
    assert result.order == base.order
    poles, base_poles = np.sort_complex(result.poles), np.sort_complex(base.poles)
    assert np.max(np.abs(poles - base_poles) / np.abs(base_poles)) < 1e-6
    # The zeros sit in a flat valley of the cost with the delay; they agree far inside their own
    # uncertainty (the delay's is ~0.2 samples here).
    assert np.max(np.abs(np.sort_complex(result.zeros) - np.sort_complex(base.zeros))) < 5e-3
    assert result.delay_samples == pytest.approx(base.delay_samples, abs=1e-2)
    for key, value in fbsd_hz(result.model).items():
        assert value == pytest.approx(fbsd_hz(base.model)[key], rel=1e-6)
    gain = factor if channel == "response" else 1.0 / factor
    assert result.model.dc_gain == pytest.approx(base.model.dc_gain * gain, rel=1e-6)


# --- hard cases: within the interval, or a warning that says why ---------------------------------

CASES = {
    "rising noise 1 %": (BASE, None),
    "rising noise 3 %": (BASE.scaled(reference_noise=0.03, response_noise=0.03), None),
    "rising noise 10 %": (BASE.scaled(reference_noise=0.10, response_noise=0.10), None),
    "interferometer noise on the reference": (BASE.scaled(reference_noise=0.0, interferometer_noise=0.02), None),
    "skew of +0.4 sample": (BASE.scaled(skew_samples=0.4), None),
    "skew of −0.4 sample": (BASE.scaled(skew_samples=-0.4), None),
    "delay of +3 samples": (BASE.scaled(skew_samples=3.0), None),
    "delay of −3 samples": (BASE.scaled(skew_samples=-3.0), "leads the reference"),
    "baseline drift": (BASE.scaled(drift_per_s=20.0), None),
    "bipolar pulse": (BASE.scaled(bipolar_ratio=0.5), None),
    "truncated record": (BASE.scaled(cut_s=300e-6), "record ends before"),
    "second mode beyond the excitation": (BASE.scaled(width_s=38.6e-6, truth=AccelerometerTruth(
        modes=(Mode(27_000.0, 0.05), Mode(180_000.0, 0.02)), sensitivity=2.5)), None),
    "amplifier low-pass in the band": (BASE.scaled(truth=AccelerometerTruth(
        modes=(Mode(27_000.0, 0.05),), lowpass_hz=60_000.0, sensitivity=2.5)), None),
}


@pytest.mark.parametrize("name", list(CASES))
def test_hard_case_is_within_its_interval_or_says_why(name: str) -> None:
    case, expected_warning = CASES[name]
    truth = truth_figures(case)
    ident = identify(record(case, 3))
    # The default draws: a 95 % interval's ends from 80 draws scatter by ~0.3 u, and a single
    # shot at ~2 u then lands outside as often as the ends do (the f_n of seed 3 at 1 % noise).
    result = evaluate(ident, AnalysisOptions(draws=DEFAULT_DRAWS, seed=1, **NO_CHAIN))
    warnings = ident.warnings + result.warnings
    if expected_warning is not None:
        assert any(expected_warning in w for w in warnings), warnings
    figures = {"dc_gain": result.dc_gain, "natural_frequency_hz": result.natural_frequency_hz,
               "damping_ratio": result.damping_ratio, "fbsd_5": result.fbsd_hz["5"],
               "fbsd_10": result.fbsd_hz["10"], "shock_sensitivity": result.shock_sensitivity}
    outside = {k: (e.value, e.interval, truth[k]) for k, e in figures.items()
               if e is None or not e.interval[0] <= truth[k] <= e.interval[1]}
    if expected_warning is None:
        assert not outside, outside
    assert ident.delay_samples >= 0.0
    main = ident.main_mode
    assert main is not None and main["natural_frequency_hz"] == pytest.approx(27_000.0, rel=0.01)
    # Modes the pulse cannot excite are never claimed.
    lo, hi = ident.supported_band_hz
    assert all(m["supported"] == (lo <= m["natural_frequency_hz"] <= hi) for m in ident.modes
               if m["natural_frequency_hz"] is not None and not m["nyquist"])


def test_reference_noise_does_not_bias_the_model() -> None:
    """Errors-in-variables: a reference with strong interferometer noise (f² spectrum up to
    100 kHz, 15 % of the peak) and a clean response; over shots the estimates scatter around the
    truth, within their uncertainty. A fit that trusts the reference (its noise weight set to
    zero) gives, on the same shots, FBSD ±5 % +2.8 % (mean +1.7 u); this one +0.7 % (+0.3 u).
    (The supported band, cut where the reference's SNR falls below 20 dB, already keeps most
    of the attenuation bias out; the weighting removes the rest.)"""
    case = BASE.scaled(reference_noise=0.0, interferometer_noise=0.15, interferometer_band_hz=100e3,
                       response_noise=0.002)
    truth = truth_figures(case)
    z = {k: [] for k in ("dc_gain", "natural_frequency_hz", "fbsd_5")}
    for seed in range(6):
        result = evaluate(identify(record(case, 40 + seed)), AnalysisOptions(draws=60, seed=seed, **NO_CHAIN))
        for k, e in (("dc_gain", result.dc_gain), ("natural_frequency_hz", result.natural_frequency_hz),
                     ("fbsd_5", result.fbsd_hz["5"])):
            if e is not None:  # a noisy reference may not support the resonance: then it is not claimed
                z[k].append((e.value - truth[k]) / e.u)
    for k, values in z.items():
        assert len(values) >= 4 and abs(np.mean(values)) < 1.0, (k, values)  # no systematic offset beyond the uncertainty
