"""The one-line summary of a shot's figures (hopkinson shot, campaign progress) says what the
report says: value ± U, and no natural frequency for a mode the excitation does not support."""

from __future__ import annotations

from hopkinson.rig.campaign_results import result_line

MODE = {"kind": "complex", "natural_frequency_hz": 27_110.0, "damping_ratio": 0.0449}


def test_an_unsupported_mode_is_not_claimed_and_an_fbsd_edge_beyond_the_band_is_a_bound() -> None:
    results = {
        "model": {"order": 2, "dc_gain": 1.0},
        "identification": {"main_mode": None, "modes": [{**MODE, "supported": False}],
                           "supported_band_hz": [0.0, 12_270.0]},
        "fbsd_hz": {"5": 5_918.0, "10": 14_000.0},
        "fbsd_bounds": {"10": {"lower_bound_hz": 12_270.0, "reason": "unsupported by the excitation"}},
        "uncertainty": {"fbsd_hz": {"5": {"value": 5_918.0, "u": 11.5, "interval": [5_895.0, 5_941.0]}}},
    }
    line = result_line(results)
    assert "27.1" not in line and "f_n" not in line.replace("f_n not claimed", "")
    assert "no resonance in the supported band (0-12.3 kHz): f_n not claimed" in line
    assert "FBSD ±5 % 5.918 ± 0.023 kHz, ±10 % > 12.3 kHz (unsupported by the excitation)" in line


def test_a_supported_mode_is_given_with_its_expanded_uncertainty() -> None:
    results = {
        "model": {"order": 2, "dc_gain": 1.0},
        "identification": {"main_mode": MODE, "modes": [MODE]},
        "fbsd_hz": {"5": 5_918.0, "10": 8_178.0},
        "uncertainty": {"main_mode": {"natural_frequency_hz": {"value": 27_110.0, "u": 60.0,
                                                               "interval": [26_990.0, 27_230.0]}}},
    }
    assert result_line(results) == ("order 2, f_n 27.11 ± 0.12 kHz, zeta 0.0449, "
                                    "FBSD ±5 % 5.918 kHz, ±10 % 8.178 kHz")
