"""The results strip: the shot's key figures (analysis.key_figures) as the panel shows them,
value ± U where the shot carries its uncertainty, and the DCM's check with its verdict."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hopkinson.analysis.excitation import excitation_summary
from hopkinson.drivers.sim.shock import half_sine_m_s2


def test_pulse_figures_come_from_the_excitation_without_a_reduction(qtbot):
    """A record analysed without an interferometer reduction: peak and 10 % width of the
    reference pulse, checked against the half-sine's closed form."""
    from hopkinson.analysis.key_figures import KeyFigures
    from hopkinson.ui.plots import ResultsStrip

    dt, width_s, peak = 1e-7, 50e-6, 2.0e5
    t = np.arange(3000) * dt
    results = {"excitation": excitation_summary(half_sine_m_s2(t, width_s, peak, 50e-6), dt).to_dict()}
    width_10 = width_s * (1 - 2 * math.asin(0.1) / math.pi)
    kf = KeyFigures.from_results(results)
    assert kf.pulse_width_s.value == pytest.approx(width_10, rel=1e-3)
    assert kf.peak_acceleration_m_s2.value == pytest.approx(peak, rel=1e-3)
    strip = ResultsStrip()
    qtbot.addWidget(strip)
    strip.show_figures(kf)
    assert strip.values["pulse"].text() == f"{peak / 1e3:.0f} km/s² ({peak / 9.80665:.0f} g), {width_10 * 1e6:.1f} µs"


def test_the_strip_shows_value_plus_minus_u_and_the_dcm_verdict(qtbot):
    from hopkinson.analysis.key_figures import KeyFigures
    from hopkinson.reports.data import CompensationCheck
    from hopkinson.ui.plots import ResultsStrip

    u_fn = 108.0  # Hz: U = 1.96 u = 211.7 Hz -> two significant digits: 0.21 kHz
    results = {
        "model": {"order": 2, "dc_gain": 1.0001, "sample_interval_s": 1e-6},
        "identification": {"fit_percent": 99.65, "main_mode": {"natural_frequency_hz": 27001.3, "damping_ratio": 0.05}},
        "reduction": {"response_unit": "m/s^2", "shock_sensitivity": 1.61},
        "fbsd_hz": {"5": 5911.3, "10": 8168.5},
        "fbsd_bounds": {"10": {"lower_bound_hz": 18000.0, "reason": "unsupported by the excitation"}},
        "uncertainty": {"method": "monte-carlo", "draws": 200, "coverage_probability": 0.95,
                        "dc_gain": {"value": 1.0001, "u": 0.004, "interval": [0.99226, 1.01794]},
                        "main_mode": {"natural_frequency_hz": {"value": 27001.3, "u": u_fn,
                                                               "interval": [26789.6, 27213.0]}},
                        "fbsd_hz": {"5": {"value": 5911.3, "u": 47.3, "interval": [5818.6, 6004.0]}},
                        "budget": [{"source": "grating pitch", "u_rel": 0.0005}]},
        "dcm": {"compensated_fbsd_hz": {"5": 17730.0, "10": 21540.0}, "recommended": False,
                "not_recommended_reason": "the compensated RMS error exceeds the uncompensated one",
                "noise_gain": 3.2, "band_limit_hz": 40000.0,
                "check": {"rms_error_pct": {"uncompensated": 4.95, "compensated": 6.1},
                          "peak_error_pct": {"uncompensated": 60.7, "compensated": -0.7}}},
    }
    strip = ResultsStrip()
    qtbot.addWidget(strip)
    kf = KeyFigures.from_results(results)
    strip.show_figures(kf, CompensationCheck.of(kf))
    v = strip.values
    assert v["resonance"].text() == "27.00 ± 0.21 kHz"  # value to the decimals of U (GUM 7.2.6)
    assert v["fbsd_5"].text() == "5.911 ± 0.093 kHz"
    assert v["fbsd_10"].text() == "> 18.0 kHz" and "unsupported" in v["fbsd_10"].toolTip()
    assert v["sensitivity"].text() == "1.000 ± 0.013 × nominal"
    assert v["shock"].text() == "1.6100 × nominal"  # no uncertainty stored for it: the value alone
    assert v["comp_5"].text() == "17.73 kHz"
    assert v["check_rms"].text() == "4.95 % → 6.1 %" and v["check_peak"].text() == "60.7 % → -0.7 %"
    assert v["band_limit"].text() == "≤ 40.0 kHz" and v["noise_gain"].text() == "×3.2"
    assert not strip.verdict.isHidden()
    assert strip.verdict.text() == "DCM NOT RECOMMENDED: the compensated RMS error exceeds the uncompensated one"
