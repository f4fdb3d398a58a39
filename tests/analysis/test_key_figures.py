"""KeyFigures: a shot's headline numbers from a results dict, the one place they are computed."""

from __future__ import annotations

import pytest

from hopkinson.analysis.key_figures import Figure, KeyFigures

RESULTS = {
    "model": {"dc_gain": 2.0e-7, "order": 4, "sample_interval_s": 1e-6, "delay_samples": 0.5},
    "identification": {
        "order": 4, "fit_percent": 99.1, "order_selection": "test",
        "modes": [
            {"kind": "real", "natural_frequency_hz": 5e3, "damping_ratio": 1.0, "supported": True},
            {"kind": "complex", "natural_frequency_hz": 27e3, "damping_ratio": 0.05, "supported": True},
            {"kind": "complex", "natural_frequency_hz": 200e3, "damping_ratio": 0.02, "supported": False},
        ],
        "supported_band_hz": [0.0, 38e3],
    },
    "fbsd_hz": {"5": 6.1e3, "10": 60e3},
    "fbsd_bounds": {"10": {"lower_bound_hz": 38e3, "reason": "unsupported by the excitation"}},
    "reduction": {"shock_sensitivity": 2.1e-7, "pulse_width_s": 3.86e-5, "peak_acceleration_m_s2": 5e5,
                  "peak_velocity_m_s": 12.0, "response_unit": "V"},
    "uncertainty": {
        "method": "GUM-S1 Monte Carlo", "draws": 400, "coverage_probability": 0.95,
        "dc_gain": {"value": 2.0e-7, "u": 1e-9, "interval": [1.98e-7, 2.02e-7]},
        "main_mode": {"natural_frequency_hz": {"value": 27e3, "u": 50.0, "interval": [26.9e3, 27.1e3]},
                      "damping_ratio": {"value": 0.05, "u": 0.001, "interval": [0.048, 0.052]}},
        "fbsd_hz": {"5": {"value": 6.1e3, "u": 30.0, "interval": [6.04e3, 6.16e3]}},
        "budget": [{"source": "response noise", "u_rel": 0.004}],
        "warnings": ["an uncertainty warning"],
    },
    "warnings": ["a warning"],
}


def test_main_mode_is_the_lowest_supported_complex_pair_not_modes_0() -> None:
    figures = KeyFigures.from_results(RESULTS)
    assert figures.natural_frequency_hz.value == 27e3
    assert figures.natural_frequency_hz.interval == (26.9e3, 27.1e3)
    assert figures.damping_ratio.u == 0.001


def test_figures_carry_uncertainty_and_bounds() -> None:
    figures = KeyFigures.from_results(RESULTS)
    assert figures.has_uncertainty
    assert figures.sensitivity.value == 2.0e-7 and figures.sensitivity.expanded == pytest.approx(2e-9)
    assert figures.fbsd_text("10") == "> 38 kHz (unsupported by the excitation)"
    assert figures.fbsd_text("5") == "6.100 ± 0.060 kHz"  # two significant digits of U
    assert figures.delay_s == pytest.approx(0.5e-6)
    assert figures.warnings == ("a warning", "an uncertainty warning")
    assert figures.to_dict()["fbsd_hz"]["5"]["interval"] == [6.04e3, 6.16e3]


def test_old_results_without_uncertainty_still_give_figures() -> None:
    old = {"model": {"dc_gain": 1.0, "order": 2}, "fbsd_hz": {"5": 6e3, "10": 8e3},
           "identification": {"modes": [{"kind": "pair", "natural_frequency_hz": 27e3, "damping_ratio": 0.05}]}}
    figures = KeyFigures.from_results(old)
    assert not figures.has_uncertainty
    assert figures.natural_frequency_hz == Figure(27e3)
    assert figures.fbsd_text("5") == "6 kHz"
    assert figures.shock_sensitivity is None


def test_the_quasi_static_gain_is_read_with_its_amplitude_or_why_not() -> None:
    figures = KeyFigures.from_results({**RESULTS, "static_gain": {"value": 2.01e-7, "u": 1e-10,
                                                                  "amplitude_m_s2": 3.5e5}})
    assert figures.static_gain.value == 2.01e-7 and figures.static_gain.u == 1e-10
    assert figures.static_gain.interval == pytest.approx((2.01e-7 - 1.96e-10, 2.01e-7 + 1.96e-10), rel=1e-4)
    assert figures.static_gain_amplitude_m_s2 == 3.5e5 and figures.shot_specific_u("static_gain") == 1e-10
    why = KeyFigures.from_results({**RESULTS, "static_gain": {"not_determined": "fewer than 4 fitted bins"}})
    assert why.static_gain is None and why.static_gain_not_determined == "fewer than 4 fitted bins"
    old = KeyFigures.from_results(RESULTS)  # results written before it
    assert old.static_gain is None and old.static_gain_not_determined is None
