"""The rig configuration's analysis constants reach a shot's analysis: [analysis] dcm_widening
and dcm_noise_gain_limit drive the automatic DCM, [uncertainty] the reference chain and the
draws; `hopkinson shot --dcm-ratio` takes auto (the default) or a number, like `hopkinson dcm
--ratio`, and refuses anything else before the rig moves."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from hopkinson.rig.cli.main import main
from hopkinson.rig.shotfile import read_shot

REPO = Path(__file__).resolve().parents[2]
CHANGED = {"dcm_widening": "5.0", "dcm_noise_gain_limit": "6.0", "grating_pitch_rel": "3e-4", "draws": "120",
           "transverse_sensitivity_rel": "0.01", "asymmetry_bound_rel": "0.04"}


def _rig_toml(tmp_path: Path) -> Path:
    text = (REPO / "config" / "rig-sim.toml").read_text(encoding="utf-8")
    for key, value in {**CHANGED, "charge_s": "3.0", "safe_s": "3.0"}.items():
        text, n = re.subn(rf"^(# )?{key} = .*$", f"{key} = {value}", text, flags=re.M)  # dcm_widening: unset
        assert n == 1, key
    path = tmp_path / "rig.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _shot(tmp_path: Path, *extra: str) -> list[str]:
    sim = tmp_path / "sim.toml"
    sim.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
    return ["shot", "--sim", "--config", str(_rig_toml(tmp_path)), "--sim-config", str(sim), "--out",
            str(tmp_path / "shots"), "--pressure-bar", "1.0", "--yes", "--json", "--no-uncertainty", *extra]


def test_the_rig_configs_dcm_and_uncertainty_constants_reach_the_analysis(tmp_path: Path, capsys) -> None:
    assert main(_shot(tmp_path)) == 0  # --dcm-ratio left at auto
    result = json.loads(capsys.readouterr().out)
    results = read_shot(result["shot_path"]).results
    dcm, params = results["dcm"], results["params"]
    assert params["dcm_ratio"] is None  # auto: the analysis chose r for the configured widening
    assert dcm["target_widening"] == 5.0 and dcm["noise_gain_limit"] == 6.0
    assert dcm["noise_gain"] <= 6.0
    assert dcm["reached_widening"] >= 5.0 or dcm["widening_note"]  # reached, or says why not
    assert params["dcm_widening"] == 5.0 and params["dcm_noise_gain_limit"] == 6.0
    assert params["u_grating_pitch_rel"] == 3e-4 and params["draws"] == 120


@pytest.mark.parametrize("value", ["0", "-2", "nan", "inf", "soon"])
def test_a_bad_dcm_ratio_is_one_line_and_nothing_moves(tmp_path: Path, capsys, value: str) -> None:
    state = tmp_path / "state.json"
    assert main([*_shot(tmp_path, "--dcm-ratio", value), "--sim-state-file", str(state)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert err == f"hopkinson: error: --dcm-ratio: 'auto' or a positive number, got '{value}'\n"
    assert not state.exists()  # the simulated rig was never started


def test_a_requests_analysis_overrides_merge_over_the_config_and_name_a_bad_value(tmp_path: Path) -> None:
    """ShotRequest.analysis: options given win over the configuration's, the others stay the
    configuration's; a bad value is refused naming the option; an unknown option cannot be asked;
    the shot file's settings record the given options (the sensor's own apart) in the first
    files' order."""
    from hopkinson.analysis.options import AnalysisOverrides
    from hopkinson.rig.config import load_rig_config
    from hopkinson.rig.shot import ShotRequest, ShotRequestError, analysis_params

    config = load_rig_config(_rig_toml(tmp_path))
    request = ShotRequest(pressure_bar=1.0, out_dir=tmp_path, analysis=AnalysisOverrides(
        draws=80, dcm_damping=0.6, max_order=7, sensitivity_v_per_m_s2=3e-7, transverse_sensitivity_rel=0.1))
    params = analysis_params(request, config, {"amplifier_gain": 20.0})
    assert (params.draws, params.dcm_damping, params.max_order) == (80, 0.6, 7)
    assert (params.sensitivity_v_per_m_s2, params.transverse_sensitivity_rel, params.amp_gain) == (3e-7, 0.1, 20.0)
    assert params.dcm_widening == 5.0 and params.u_grating_pitch_rel == 3e-4  # the configuration's
    assert params.asymmetry_bound_rel == 0.04  # the rig's, where the request states none for its sensor
    assert list(request.recorded_options().items()) == [("max_order", 7), ("dcm_damping", 0.6), ("draws", 80)]
    with pytest.raises(ShotRequestError, match=r"^analysis option max_order: an integer from 1 to 60, got 0$"):
        ShotRequest(pressure_bar=1.0, out_dir=tmp_path, analysis=AnalysisOverrides(max_order=0)).check(config)
    with pytest.raises(TypeError, match="no_such_option"):
        AnalysisOverrides(no_such_option=1)
