"""The sensor's sensitivity unit and tolerance (issue 42): given in a plan or a shot request,
checked before anything moves, and recorded with the shot so its verdict and its absolute
sensitivity come from the shot's own data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.options import AnalysisOverrides
from hopkinson.drivers.digitizer import Waveform
from hopkinson.rig.config import load_rig_config
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan import load_plan
from hopkinson.rig.shot import (
    CapturedShot,
    ShotRequest,
    ShotRequestError,
    analysis_params,
    shot_meta,
)

REPO = Path(__file__).resolve().parents[2]
PLAN = """
name = "t"
operator = "op"
[accelerometer]
model = "M"
serial = "S"
sensitivity_v_per_m_s2 = 2.0e-7
{extra}
[[shots]]
pressure_bar = 2
projectile = 3
"""


def plan_with(tmp_path: Path, extra: str) -> Path:
    path = tmp_path / "plan.toml"
    path.write_text(PLAN.format(extra=extra), encoding="utf-8")
    return path


def test_a_plan_names_the_unit_and_the_tolerance(tmp_path: Path) -> None:
    plan = load_plan(plan_with(tmp_path, 'sensitivity_unit = "uV/(m/s^2)"\ntolerance_percent = 5.0'))
    assert plan.accelerometer.sensitivity_unit == "µV/(m/s²)"  # ASCII spelling, stored as the unit's name
    assert plan.accelerometer.tolerance_percent == 5.0
    assert load_plan(plan_with(tmp_path, "")).accelerometer.sensitivity_unit is None


@pytest.mark.parametrize(("extra", "message"), [
    ('sensitivity_unit = "furlongs"', "accelerometer.sensitivity_unit: sensitivity unit 'furlongs' is not known"),
    ("tolerance_percent = 0", "accelerometer.tolerance_percent: must be > 0 and < 100"),
    ("tolerance_percent = 150", "accelerometer.tolerance_percent: must be > 0 and < 100"),
])
def test_a_bad_unit_or_tolerance_is_refused_naming_the_key(tmp_path: Path, extra: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_plan(plan_with(tmp_path, extra))


def test_a_request_checks_the_nominal_in_its_unit(tmp_path: Path) -> None:
    config = load_rig_config(REPO / "config" / "rig-sim.toml")
    good = ShotRequest(pressure_bar=2.0, analysis=AnalysisOverrides(sensitivity_v_per_m_s2=2e-7), sensitivity_unit="µV/(m/s²)",
                       tolerance_percent=5.0, out_dir=tmp_path)
    good.check(config)
    # 0.2 µV/(m/s²) typed as pC/(m/s²): a charge sensor of 2e-7 C/(m/s²) = 200 000 pC/(m/s²) is not plausible
    with pytest.raises(ShotRequestError, match=r"sensitivity: sensitivity 200000 pC/\(m/s²\) is outside the plausible range 0.0001 … 1000 pC"):
        ShotRequest(pressure_bar=2.0, analysis=AnalysisOverrides(sensitivity_v_per_m_s2=2e-7), sensitivity_unit="pC/(m/s²)",
                    out_dir=tmp_path).check(config)
    with pytest.raises(ShotRequestError, match="tolerance_percent: must be between 0 and 100 %"):
        ShotRequest(pressure_bar=2.0, tolerance_percent=0.0, out_dir=tmp_path).check(config)


def test_the_shot_file_settings_record_them(tmp_path: Path) -> None:
    config = load_rig_config(REPO / "config" / "rig-sim.toml")
    wave = Waveform(channel="CH1", codes=np.zeros(8, dtype=np.int16), scale_v=1e-3, offset_v=0.0, sample_interval_s=1e-8,
                    trigger_index=2, code_range=(-32768.0, 32767.0))
    captured = CapturedShot({"doppler": wave, "response": wave})
    request = ShotRequest(pressure_bar=2.0, sensitivity_unit="mV/g", tolerance_percent=3.0, out_dir=tmp_path)
    settings = shot_meta(request, config, {}, captured).config["shot_settings"]
    assert settings["sensitivity_unit"] == "mV/g" and settings["sensitivity_tolerance_percent"] == 3.0
    plain = shot_meta(ShotRequest(pressure_bar=2.0, out_dir=tmp_path), config, {}, captured).config["shot_settings"]
    assert "sensitivity_unit" not in plain and "sensitivity_tolerance_percent" not in plain
    assert "transverse_sensitivity_rel" not in plain and "asymmetry_bound_rel" not in plain
    # what the sensor states (a plan's, the panel's): what a later re-analysis needs (rig.reanalysis)
    stated = ShotRequest(pressure_bar=2.0, analysis=AnalysisOverrides(transverse_sensitivity_rel=0.03,
                                                                      asymmetry_bound_rel=0.045), out_dir=tmp_path)
    settings = shot_meta(stated, config, {}, captured).config["shot_settings"]
    assert (settings["transverse_sensitivity_rel"], settings["asymmetry_bound_rel"]) == (0.03, 0.045)
    assert "asymmetry_bound_rel" not in settings["analysis_options"]  # recorded once, under its own key


def test_a_campaign_shot_carries_the_plans_unit_and_tolerance(tmp_path: Path) -> None:
    from types import SimpleNamespace

    from hopkinson.rig.campaign_setup import shot_request

    plan = load_plan(plan_with(tmp_path, 'sensitivity_unit = "mV/g"\ntolerance_percent = 2.5\n'
                                         'transverse_sensitivity_rel = 0.01\nasymmetry_bound_rel = 0.07'))
    run = SimpleNamespace(shots_dir=tmp_path, campaign_id="t-run")
    request = shot_request(plan, plan.shots[0], run)  # type: ignore[arg-type]
    assert (request.sensitivity_unit, request.tolerance_percent) == ("mV/g", 2.5)
    assert (request.analysis.transverse_sensitivity_rel, request.analysis.asymmetry_bound_rel) == (0.01, 0.07)
    params = analysis_params(request, load_rig_config(REPO / "config" / "rig-sim.toml"), {})
    assert (params.transverse_sensitivity_rel, params.asymmetry_bound_rel) == (0.01, 0.07)  # the sensor's, not the rig's
    plain = shot_request(load_plan(plan_with(tmp_path, "")), plan.shots[0], run)  # type: ignore[arg-type]
    assert (plain.analysis.transverse_sensitivity_rel, plain.analysis.asymmetry_bound_rel) == (None, None)
    with pytest.raises(ConfigError, match=r"accelerometer\.asymmetry_bound_rel"):
        load_plan(plan_with(tmp_path, "asymmetry_bound_rel = 1.5"))


def test_a_shots_judgement_reads_its_unit_nominal_tolerance_and_target() -> None:
    from hopkinson.analysis.verdict import Check, Decision, Status
    from hopkinson.rig.shot_verdict import judge

    results = {
        "params": {"sensitivity_v_per_m_s2": 0.312e-6},  # the nominal the analysis divided by
        "model": {"dc_gain": 0.627, "order": 4, "sample_interval_s": 1e-6},
        "identification": {"fit_percent": 98.0, "supported_band_hz": [60.0, 66e3],
                           "main_mode": {"natural_frequency_hz": 29.7e3, "damping_ratio": 0.05}},
        "fbsd_hz": {"5": 6.3e3},
        "reduction": {"response_unit": "m/s^2", "peak_acceleration_m_s2": 40_000 * 9.80665,
                      "shock_sensitivity": 0.95},
        "dcm": {"recommended": True},
    }
    settings = {"sensitivity_unit": "µV/(m/s²)", "sensitivity_tolerance_percent": 5.0,
                "level_control": {"target_peak_m_s2": 50_000 * 9.80665}}
    j = judge(results, settings)
    assert j.sensitivity.text() == "0.1956 µV/(m/s²)" and j.sensitivity.ratio == 0.627
    assert j.verdict.finding(Check.SENSITIVITY).status == Status.FLAG  # −37 % against ±5 %
    assert j.verdict.decision == Decision.REPEAT and "target 50\u00a0000 g, −20.0 %" in j.verdict.reason
    assert j.shock_sensitivity.text() == "0.2964 µV/(m/s²)"
    mv = judge(results, {"sensitivity_unit": "mV/g"})  # 0.1956 µV/(m/s²) × 9.80665 m/s² per g
    assert mv.sensitivity.text() == "0.001918 mV/g"
    failed = judge(None, settings, "analysis failed: the response is clipped")
    assert failed.verdict.decision == Decision.REPEAT and failed.sensitivity is None
