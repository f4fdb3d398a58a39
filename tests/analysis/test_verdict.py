"""The shot verdict (analysis.verdict) and sensitivity units (analysis.sensitivity_units),
each judged on hand-made key figures whose right answer is known by construction."""

from __future__ import annotations

import copy

import pytest

from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.analysis.sensitivity_units import (
    G_M_S2,
    UNITS,
    absolute_sensitivity,
    canonical_name,
    check_plausible,
    sensitivity_unit,
)
from hopkinson.analysis.verdict import (
    Check,
    Decision,
    Status,
    VerdictCriteria,
    rank_warnings,
    shot_verdict,
)

# A good shot: fit 97.6 %, band 0.06–66 kHz, resonance at 29.7 kHz excited, 50 614 g, DC gain
# 0.978 of nominal (response in m/s², i.e. divided by the nominal), DCM recommended.
GOOD = {
    "model": {"dc_gain": 0.978, "order": 4, "sample_interval_s": 1e-6},
    "identification": {"order": 4, "fit_percent": 97.6, "supported_band_hz": [61.0, 66_300.0],
                       "main_mode": {"natural_frequency_hz": 29_746.0, "damping_ratio": 0.049}},
    "fbsd_hz": {"5": 6_363.0, "10": 8_810.0},
    "reduction": {"response_unit": "m/s^2", "peak_acceleration_m_s2": 50_614 * G_M_S2, "pulse_width_s": 41.6e-6,
                  "shock_sensitivity": 1.53},
    "dcm": {"recommended": True},
    "warnings": [],
}


def figures(**changes: object) -> KeyFigures:
    results = copy.deepcopy(GOOD)
    for path, value in changes.items():
        section, _, key = path.partition("__")
        if value is None:
            results[section].pop(key, None)
        else:
            results[section][key] = value
    return KeyFigures.from_results(results)


def test_a_good_shot_is_accepted_with_every_check_in_its_line() -> None:
    verdict = shot_verdict(figures(), target_peak_m_s2=50_000 * G_M_S2)
    assert verdict.decision == Decision.ACCEPT
    assert verdict.reason == "every check passed"
    line = verdict.line()
    assert line.startswith("ACCEPT — fit 97.6 %")
    for text in ("band 0.061–66.3 kHz", "resonance excited (29.7 kHz)", "level 50\u00a0614 g (target 50\u00a0000 g, +1.2 %)",
                 "sensitivity −2.2 % from nominal", "DCM recommended"):
        assert text in line, (text, line)


def test_a_poor_fit_is_repeated_and_named_first() -> None:
    # the shot: fit 43 %, the resonance beyond the band, sensitivity 0.995
    verdict = shot_verdict(figures(identification__fit_percent=43.0, identification__main_mode={},
                                   model__dc_gain=0.995))
    assert verdict.decision == Decision.REPEAT
    assert verdict.reason == "fit 43.0 % (below 90 %)"
    assert verdict.line().startswith("REPEAT — fit 43.0 % (below 90 %) · band")
    assert verdict.finding(Check.RESONANCE).status == Status.NOTE
    assert "resonance not excited" in verdict.line()


def test_the_level_outside_its_tolerance_is_repeated() -> None:
    target = 50_000 * G_M_S2
    low = shot_verdict(figures(reduction__peak_acceleration_m_s2=44_000 * G_M_S2), target_peak_m_s2=target)
    assert low.decision == Decision.REPEAT and "−12.0 %" in low.reason and "outside ±10 %" in low.reason
    inside = shot_verdict(figures(reduction__peak_acceleration_m_s2=45_500 * G_M_S2), target_peak_m_s2=target)
    assert inside.decision == Decision.ACCEPT  # −9 %: within ±10 %
    tight = shot_verdict(figures(reduction__peak_acceleration_m_s2=45_500 * G_M_S2), VerdictCriteria(
        level_tolerance_rel=0.05), target_peak_m_s2=target)
    assert tight.decision == Decision.REPEAT


def test_a_sensitivity_beyond_tolerance_is_flagged_not_repeated() -> None:
    # SN-24017 analysed against nominal 0.312 µV/(m/s²) reads 0.627× nominal: −37 %
    verdict = shot_verdict(figures(model__dc_gain=0.627), VerdictCriteria(tolerance_percent=5.0))
    assert verdict.decision == Decision.ACCEPT
    found = verdict.finding(Check.SENSITIVITY)
    assert found.status == Status.FLAG and "−37.3 % from nominal: OUT OF TOLERANCE (±5 %)" in found.text
    assert verdict.reason == found.text
    within = shot_verdict(figures(model__dc_gain=0.97), VerdictCriteria(tolerance_percent=5.0))
    assert within.finding(Check.SENSITIVITY).status == Status.OK


def test_requiring_the_resonance_repeats_a_shot_that_did_not_excite_it() -> None:
    kf = figures(identification__main_mode={})
    assert shot_verdict(kf).decision == Decision.ACCEPT
    assert shot_verdict(kf, VerdictCriteria(require_resonance=True)).decision == Decision.REPEAT


def test_a_failed_analysis_is_repeated_with_its_reason() -> None:
    verdict = shot_verdict(None, analysis_error="analysis failed: the reference is clipped\n(channel doppler)")
    assert verdict.decision == Decision.REPEAT
    assert verdict.reason == "analysis failed: the reference is clipped (channel doppler)"


def test_figures_not_determined_are_said_so() -> None:
    verdict = shot_verdict(figures(model__dc_gain=None, reduction__peak_acceleration_m_s2=None))
    assert verdict.decision == Decision.REPEAT
    assert verdict.finding(Check.SENSITIVITY).text == "sensitivity not determined"
    assert verdict.finding(Check.LEVEL).text == "peak acceleration not determined"
    no_band = shot_verdict(figures(identification__supported_band_hz=None))
    assert no_band.decision == Decision.REPEAT and "no supported band" in no_band.reason
    bound = KeyFigures.from_results({**copy.deepcopy(GOOD), "fbsd_bounds": {
        "5": {"lower_bound_hz": 66_300.0, "reason": "beyond the supported band"}}})
    assert "FBSD ±5 % > 66.3 kHz" in shot_verdict(bound).finding(Check.BAND).text


def test_dcm_not_recommended_is_a_note_with_its_reason() -> None:
    verdict = shot_verdict(figures(dcm__recommended=False, dcm__not_recommended_reason="noise gain ×9 above ×4"))
    assert verdict.decision == Decision.ACCEPT
    assert verdict.finding(Check.DCM).text == "DCM not recommended (noise gain ×9 above ×4)"


def test_criteria_out_of_range_are_refused() -> None:
    with pytest.raises(ValueError, match="level_tolerance_rel"):
        VerdictCriteria(level_tolerance_rel=0.0)
    with pytest.raises(ValueError, match="tolerance_percent"):
        VerdictCriteria(tolerance_percent=-1.0)


def test_warnings_that_make_figures_wrong_come_first_without_repeats() -> None:
    ranked = rank_warnings(["record ends early", "the response channel is clipped", "record ends early",
                            "model error 3x noise", "the amplifier overloaded"])
    assert ranked == ("the response channel is clipped", "the amplifier overloaded", "record ends early",
                      "model error 3x noise")


# -- units -------------------------------------------------------------------------------------
def test_units_convert_by_their_definitions() -> None:
    assert sensitivity_unit("mV/g").to_si(1.0) == pytest.approx(1e-3 / 9.80665)
    assert sensitivity_unit("uV/(m/s^2)").name == "µV/(m/s²)"
    assert sensitivity_unit("pC/(m/s^2)").input_unit == "C"
    assert sensitivity_unit("pC/g").to_si(9.80665) == pytest.approx(1e-12)
    # 1 mV/g is 101.97 µV/(m/s²)
    assert UNITS["µV/(m/s²)"].from_si(UNITS["mV/g"].to_si(1.0)) == pytest.approx(101.9716, rel=1e-6)
    assert canonical_name(" mv/G ") == "mV/g"
    with pytest.raises(ValueError, match="not known; use one of"):
        sensitivity_unit("furlongs")


def test_one_parser_reads_a_certificates_units_for_the_panel_and_the_lab() -> None:
    """analysis.sensitivity_units is the only unit parser (lab.history and lab.dcc use it): units
    beyond those offered, by their definitions; kinds never mixed."""
    from hopkinson.analysis.sensitivity_units import factor, parse

    assert sensitivity_unit("pC/(km/s²)").to_si(1.0) == pytest.approx(1e-15)
    assert sensitivity_unit("nV/g").input_unit == "V"
    assert factor("mV/g", "V/(m/s²)") == pytest.approx(1e-3 / 9.80665)
    assert factor("pC/(m/s²)", "fC/(m/s^2)") == pytest.approx(1e3)
    assert factor("pC/g", "mV/g") is None and factor("mV/furlong", "mV/g") is None
    assert parse("kV/(km/s²)") == (1e3, "V", 1e3)


def test_implausible_sensitivities_are_refused_naming_the_unit() -> None:
    check_plausible(0.312, UNITS["µV/(m/s²)"])
    check_plausible(4.0, UNITS["pC/g"])
    with pytest.raises(ValueError, match=r"27000 pC/\(m/s²\) is outside the plausible range .* pC/\(m/s²\)"):
        check_plausible(27_000.0, UNITS["pC/(m/s²)"])
    with pytest.raises(ValueError, match="µV/g"):
        check_plausible(1e-6, UNITS["µV/g"])


def test_absolute_sensitivity_is_the_same_whatever_nominal_was_entered() -> None:
    # the issue: one sensor (0.197 µV/(m/s²)) fired with nominal 0.312 and with nominal 0.200
    unit = UNITS["µV/(m/s²)"]
    first = absolute_sensitivity(0.627, 0.009, "m/s^2", unit.to_si(0.312), unit)
    second = absolute_sensitivity(0.985, 0.014, "m/s^2", unit.to_si(0.200), unit)
    assert unit.from_si(first.value_si) == pytest.approx(0.1956, abs=1e-4)
    assert unit.from_si(second.value_si) == pytest.approx(0.1970, abs=1e-4)
    assert first.text() == "0.1956 ± 0.0028 µV/(m/s²)"
    assert first.ratio_text() == "0.627× nominal (−37.3 %)"
    volts = absolute_sensitivity(2e-7, None, "V", None, unit)  # gain and nominal 1: the DC gain is absolute
    assert volts.text() == "0.2 µV/(m/s²)" and volts.ratio is None
    assert absolute_sensitivity(0.98, None, "m/s^2", None, unit) is None  # relative to an unknown nominal
