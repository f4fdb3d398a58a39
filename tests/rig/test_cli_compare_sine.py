"""`hopkinson compare-sine`: the model against a sine calibration file, with --json and a plot."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hopkinson.analysis.model import DiscreteModel
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.rig.cli.main import main

TRUTH = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),), sensitivity=2e-3)
WRONG = AccelerometerTruth(modes=(Mode(29_000.0, 0.05),), sensitivity=2e-3)


def files(tmp_path):
    b, a = WRONG.discrete_tf(1e-6)
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"model": DiscreteModel(1e-6, a, b).to_dict(), "supported_band_hz": [0, 40_000]}))
    f = np.array([160.0, 1e3, 5e3, 10e3, 15e3, 20e3])
    h = TRUTH.frequency_response(f)
    sine = tmp_path / "sine.csv"
    rows = "\n".join(f"{x},{abs(y)},{np.degrees(np.angle(y))},0.005" for x, y in zip(f, h, strict=True))
    sine.write_text("frequency_hz,magnitude,phase_deg,u_magnitude_rel\n" + rows + "\n")
    return model, sine, f


def test_json_and_plot(tmp_path, capsys):
    model, sine, f = files(tmp_path)
    plot = tmp_path / "sine.png"
    assert main(["compare-sine", str(model), str(sine), "--plot", str(plot), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    expected = 100 * (np.abs(WRONG.frequency_response(f)) / np.abs(TRUTH.frequency_response(f)) - 1)
    np.testing.assert_allclose(result["magnitude_error_pct"], expected, atol=0.1)
    assert result["consistent"][0] is True and result["consistent"][-1] is False
    assert len(result["compensated_magnitude"]) == f.size and "default DCM" in result["dcm"]
    assert result["plot"] == str(plot) and plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_text_table_and_bad_input(tmp_path, capsys):
    model, sine, _ = files(tmp_path)
    assert main(["compare-sine", str(model), str(sine)]) == 0
    text = capsys.readouterr().out
    assert "outside 2u" in text and "largest magnitude error" in text and "sine × DCM band" in text
    assert main(["compare-sine", str(model), str(sine), "--plot", str(sine)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is the input" in err
    sine.write_text("frequency_hz,magnitude\n1000,1\n")
    assert main(["compare-sine", str(model), str(sine)]) == 2
    assert "phase_deg" in capsys.readouterr().err


@pytest.mark.parametrize("reference", ["1000", "5"])
def test_reference_frequency(tmp_path, capsys, reference):
    model, sine, _ = files(tmp_path)
    code = main(["compare-sine", str(model), str(sine), "--reference-hz", reference, "--json"])
    if reference == "5":
        assert code == 2 and "outside the points" in capsys.readouterr().err
        return
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["reference_frequency_hz"] == 1000.0
    assert result["sine_magnitude"][1] == pytest.approx(1.0)


def test_a_campaign_plan_names_the_sine_file_and_the_comparison_follows(tmp_path):
    """The plan's [accelerometer] sine_calibration, relative to the plan's folder, is the file
    analysis.sine_comparison.compare_sine reads for the campaign report."""
    from hopkinson.analysis.sine_comparison import compare_sine, read_sine_calibration
    from hopkinson.rig.plan import plan_from_dict

    model, sine, _ = files(tmp_path)
    doc = {"name": "c", "operator": "o", "accelerometer": {"model": "AYZ-3", "serial": "1",
                                                         "sine_calibration": "sine.csv"},
           "shots": [{"pressure_bar": 1.0, "projectile": 3}]}
    plan = plan_from_dict(doc, tmp_path / "plan.toml")
    assert plan.accelerometer.sine_calibration == str(sine)
    b, a = WRONG.discrete_tf(1e-6)
    comparison = compare_sine(DiscreteModel(1e-6, a, b), read_sine_calibration(plan.accelerometer.sine_calibration))
    assert comparison.max_magnitude_error_pct > 1.0
