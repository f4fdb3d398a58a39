"""`hopkinson identify RECORD --sine SINE.csv` end to end: the joint model's JSON (consistency,
E_n per point), its text, the DCM from it checked on the record (`dcm --model --record`), and
bad input; on a simulated sensor with a known truth and on PTB's real record."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hopkinson.rig.cli.main import main
from tests.analysis.hard_records import Case, record
from tests.analysis.test_sine_joint import OTHER, synthetic_sine
from tests.ptb_shock import write_ptb_record_csv, write_ptb_sine_csv

PLAN = """name = "joint"
operator = "T"
[accelerometer]
model = "M"
serial = "S"
sine_calibration = "{sine}"
[[shots]]
pressure_bar = 2.0
projectile = 3
"""


def write_record(path, rec):
    np.savetxt(path, np.column_stack([rec.time_s, rec.reference, rec.response]), delimiter=",",
               header="time_s,reference,response", comments="", fmt="%.10g")
    return path


def write_sine(path, sine):
    rows = zip(sine.frequency_hz, sine.magnitude, sine.phase_deg, sine.u_magnitude_rel, sine.u_phase_deg, strict=True)
    path.write_text("frequency_hz,magnitude,phase_deg,u_magnitude_rel,u_phase_deg\n"
                    + "".join(",".join(f"{v:.10g}" for v in row) + "\n" for row in rows))
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("joint")
    case = Case()
    return (write_record(folder / "shot.csv", record(case, 3)),
            write_sine(folder / "sine.csv", synthetic_sine(case.truth, 3)),
            write_sine(folder / "other.csv", synthetic_sine(OTHER, 3)))


def test_identify_with_sine_json_then_dcm_on_the_record(files, tmp_path, capsys) -> None:
    shot, sine, _ = files
    model = tmp_path / "model.json"
    assert main(["identify", str(shot), "--sine", str(sine), "--draws", "60", "--seed", "2", "--json",
                 "-o", str(model)]) == 0
    report = json.loads(capsys.readouterr().out)
    joint = report["sine_joint"]
    assert joint["consistent"] is True and len(joint["e_n"]) == 40 and joint["model_draws"] >= 50
    assert "sine calibration" in {b["source"] for b in report["uncertainty"]["budget"]}
    assert json.loads(model.read_text())["sine_joint"]["verdict"] == joint["verdict"]
    assert main(["dcm", "--model", str(model), "--record", str(shot), "--json"]) == 0
    check = json.loads(capsys.readouterr().out)["dcm"]["check"]
    # the DCM from the joint model compensates the shock better than none
    assert abs(check["rms_error_pct"]["compensated"]) < abs(check["rms_error_pct"]["uncompensated"])


def test_identify_with_another_sensors_sine_says_so_in_text(files, capsys) -> None:
    shot, _, other = files
    assert main(["identify", str(shot), "--sine", str(other), "--no-uncertainty"]) == 0
    text = capsys.readouterr().out
    assert f"fitted with the sine calibration {other}: inconsistent" in text
    assert "largest E_n" in text and "sine ÷ shock level" in text


def test_a_bad_sine_file_is_one_line_and_exit_2(files, tmp_path, capsys) -> None:
    shot, _, _ = files
    assert main(["identify", str(shot), "--sine", str(tmp_path / "none.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "none.csv: no such file" in err
    bad = tmp_path / "bad.csv"
    bad.write_text("frequency_hz,magnitude,phase_deg\n1000,-1,0\n")
    assert main(["identify", str(shot), "--sine", str(bad)]) == 2
    assert "magnitudes must be positive" in capsys.readouterr().err


def test_ptb_record_with_its_sine_is_fitted_jointly_and_compensated(tmp_path, capsys) -> None:
    """Before, no order was stable (the free zeros put the sensor's mode on the unit circle); the
    all-pole model fits both. Checked against the sine's own FBSD edges (an independent truth)
    and the compensation's RMS error against the reference, as `hopkinson dcm --record` measures."""
    from tests.ptb_shock import SINE_FBSD_5_HZ, SINE_FBSD_10_HZ

    shot = write_ptb_record_csv(tmp_path / "ptb.csv")
    sine = write_ptb_sine_csv(tmp_path / "ptb_sine.csv")
    model = tmp_path / "model.json"
    assert main(["identify", str(shot), "--sine", str(sine), "--no-uncertainty", "--json", "-o", str(model)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["order_evidence"]["structure"] == "all_pole"
    assert report["fbsd_hz"]["5"] == pytest.approx(SINE_FBSD_5_HZ, rel=0.05)
    assert report["fbsd_hz"]["10"] == pytest.approx(SINE_FBSD_10_HZ, rel=0.05)
    assert main(["dcm", "--model", str(model), "--record", str(shot), "--json"]) == 0
    design = json.loads(capsys.readouterr().out)
    check = design["dcm"]["check"]
    assert abs(check["rms_error_pct"]["compensated"]) <= 2.0 < abs(check["rms_error_pct"]["uncompensated"])
    # the band limit lets the compensated ±5 % band reach the top of the band the shot supports
    # (×1.42 when its −3 dB point sat there) and not pass it; the peak comes within 1.5 % (−3.7 % then)
    top = report["supported_band_hz"][1]
    assert 0.9 * top <= design["compensated_fbsd_hz"]["5"] <= 1.02 * top
    assert abs(check["peak_error_pct"]["compensated"]) <= 1.5


def test_ptb_record_with_its_sine_compensates_within_two_and_one_percent(tmp_path, capsys) -> None:
    """Issue 17 item 4, as `hopkinson dcm --record` measures it (PyDynamic's route: 2.5 % /
    −0.7 %). Until stop 38 the peak came out 1.23 % low: of it 0.45 % is the record's own (the
    response peaks that much below what the model predicts from the reference), the rest the
    compensated response's roll-off at the band the shot supports, a third of that the phase of
    the IIR band limit; with the linear-phase band limit, −0.89 %."""
    shot = write_ptb_record_csv(tmp_path / "ptb.csv")
    sine = write_ptb_sine_csv(tmp_path / "ptb_sine.csv")
    model = tmp_path / "model.json"
    assert main(["identify", str(shot), "--sine", str(sine), "--no-uncertainty", "-o", str(model)]) == 0
    capsys.readouterr()
    assert main(["dcm", "--model", str(model), "--record", str(shot), "--json"]) == 0
    check = json.loads(capsys.readouterr().out)["dcm"]["check"]
    assert abs(check["rms_error_pct"]["compensated"]) <= 2.0
    assert abs(check["peak_error_pct"]["compensated"]) <= 1.0


def test_a_shot_analysis_with_the_plans_sine_fits_both(files, tmp_path) -> None:
    """The route of a plan's [accelerometer] sine_calibration and the panel's shot set-up: the
    shot request's sine_calibration reaches the analysis options, the shot's analysis fits it,
    a further sensor never inherits it (nor the first sensor's stated transverse sensitivity and
    asymmetry bound), and an unreadable file is refused before anything moves."""
    from hopkinson.analysis.options import AnalysisOptions, AnalysisOverrides
    from hopkinson.analysis.shot_analysis import analyse_record
    from hopkinson.rig.campaign_setup import shot_request
    from hopkinson.rig.config import load_rig_config
    from hopkinson.rig.plan import load_plan
    from hopkinson.rig.run_folder import RunFolder
    from hopkinson.rig.shot import ShotRequest, ShotRequestError, analysis_params, sensor_params

    _, sine, _ = files
    config = load_rig_config("config/rig-sim.toml")
    request = ShotRequest(pressure_bar=2.0, analysis=AnalysisOverrides(
        sine_calibration=str(sine), transverse_sensitivity_rel=0.01, asymmetry_bound_rel=0.08), out_dir=tmp_path)
    request.check(config)
    params = analysis_params(request, config, {})
    assert params.sine_calibration == str(sine)
    second = sensor_params(params, config)["response_2"]
    assert second.sine_calibration is None
    # nor what the first sensor's data sheet states: the rig's values, as for a sensor stating none
    assert (second.transverse_sensitivity_rel, second.asymmetry_bound_rel) == (
        config.uncertainty.transverse_sensitivity_rel, config.uncertainty.asymmetry_bound_rel) == (0.05, 0.03)
    analysis = analyse_record(record(Case(), 3), AnalysisOptions(uncertainty=False, sine_calibration=str(sine)))
    joint = analysis.to_dict()["identification"]["sine_joint"]
    assert joint["consistent"] is True and joint["source"] == str(sine)
    bad = ShotRequest(pressure_bar=2.0, analysis=AnalysisOverrides(sine_calibration=str(tmp_path / "none.csv")), out_dir=tmp_path)
    with pytest.raises(ShotRequestError, match="sine_calibration: .*none.csv: no such file"):
        bad.check(config)
    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(PLAN.format(sine=sine))
    plan = load_plan(plan_file)
    assert shot_request(plan, plan.shots[0], RunFolder(tmp_path)).analysis.sine_calibration == str(sine)
