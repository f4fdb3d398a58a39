"""`hopkinson dcm` and `hopkinson compensate`: the paper through the command line, files
in and out, and one clear line with exit 2 for every kind of bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hopkinson.analysis.dcm import apply, load_dcm
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.records import read_record, record_from_arrays, write_record
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.shock import half_sine_m_s2
from hopkinson.rig.cli.main import main

TABLE1 = "0.9740+0.1396j,0.9740-0.1396j,0.8174+0.0518j,0.8174-0.0518j"
PAPER_ARGS = ["--ratio", "12.5", "--damping", "0.707", "--extra-poles", "0.6+0.1j,0.6-0.1j"]


def run_json(capsys, argv: list[str]) -> dict:
    assert main(argv) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    return json.loads(out[0])


def run_error(capsys, argv: list[str]) -> str:
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hopkinson: error: ")
    assert "Traceback" not in captured.err
    return lines[0]


def write_model(path: Path, model: DiscreteModel) -> Path:
    path.write_text(json.dumps({"model": model.to_dict()}))
    return path


def table1_model() -> DiscreteModel:
    poles = np.array([complex(p.replace(" ", "")) for p in TABLE1.split(",")])
    a = np.real(np.poly(poles))
    return DiscreteModel(1e-6, a, [float(np.sum(a))])


def test_paper_through_the_cli(capsys):
    result = run_json(capsys, ["dcm", "--poles", TABLE1, "--sample-interval", "1e-6", *PAPER_ARGS, "--json"])
    rows = result["pole_analysis"]
    assert [round(r["response_time_samples"], 2) for r in rows] == [185.45, 185.45, 15.03, 15.03]
    assert [round(r["ratio"], 2) for r in rows] == [1.0, 1.0, 12.34, 12.34]
    dcm = result["dcm"]
    np.testing.assert_allclose(dcm["den"], [1.0, -2.8006, 2.9581, -1.3931, 0.2469], rtol=5e-4, atol=5e-5)
    np.testing.assert_allclose(
        np.array(dcm["num"]) / dcm["num"][0], np.array([15.616, -55.949, 75.3252, -45.1229, 10.1421]) / 15.616, rtol=5e-5
    )
    assert dcm["gain"] == pytest.approx(15.616, rel=2e-3)
    designed = sorted(dcm["poles"], key=lambda p: (-p[0], p[1]))[:2]
    assert [[round(x, 4) for x in p] for p in designed] == [[0.8003, -0.1641], [0.8003, 0.1641]]
    assert "fbsd_hz" not in result  # no model, no band


def test_dcm_from_model_file_and_output(tmp_path, capsys):
    model_path = write_model(tmp_path / "model.json", table1_model())
    out = tmp_path / "dcm.json"
    result = run_json(capsys, ["dcm", "--model", str(model_path), *PAPER_ARGS, "--json", "-o", str(out)])
    for key in ("5", "10"):
        assert result["compensated_fbsd_hz"][key] > 2.5 * result["fbsd_hz"][key]
    assert result["rise_time_ratio"] > 1.1
    # ±5 % settling is the paper's response time: 185.45 samples before, T'_rr = 14.836 aimed at
    st = result["settling_time_samples"]
    assert st["uncompensated"] == pytest.approx(185.45, rel=0.15)
    assert result["settling_time_ratio"] == pytest.approx(st["uncompensated"] / st["compensated"])
    assert result["settling_time_ratio"] > 5
    assert result["fbsd_detail"]["5"]["crossing"] == "above"  # the resonance: two-sided band
    saved = load_dcm(out)
    np.testing.assert_allclose(saved.num, result["dcm"]["num"])
    assert json.loads(out.read_text())["pole_analysis"] == result["pole_analysis"]


def test_text_output_says_what_was_done(tmp_path, capsys):
    assert main(["dcm", "--poles", TABLE1, "--sample-interval", "1e-6", "--ratio", "12.5", "--damping", "0.707"]) == 0
    text = capsys.readouterr().out
    assert "185.45" in text and "12.34" in text
    assert "2 pole(s) placed at z = 0" in text


def test_compensate_streams_the_response(tmp_path, capsys):
    dt = 1e-6
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),))
    b, a = truth.discrete_tf(dt)
    model = DiscreteModel(dt, a, b)
    t = np.arange(3000) * dt
    reference = half_sine_m_s2(t, 38.6e-6, 1e6, start_s=200e-6)
    response = truth.respond(reference, dt) + 0.5  # with a zero offset
    rec_path = write_record(tmp_path / "shot.npz", record_from_arrays(t, reference, response))
    dcm_path = tmp_path / "dcm.json"
    # r scales the decay envelope ζω_n: with ζ = 0.05 the new poles (ζ_e = 0.707) are only
    # faster than the resonance for r > ζ_e/ζ ≈ 14; r = 40 puts them near 77 kHz.
    main(["dcm", "--model", str(write_model(tmp_path / "m.json", model)), "--ratio", "40", "--damping", "0.707",
          "-o", str(dcm_path), "--json"])
    capsys.readouterr()
    out = tmp_path / "out.csv"
    info = run_json(capsys, ["compensate", str(rec_path), "--dcm", str(dcm_path), "-o", str(out),
                             "--block-samples", "257", "--json"])
    assert info["blocks"] == 12 and info["initial"] == "steady" and "reference" in info["what"]
    result = read_record(out)
    np.testing.assert_allclose(result.reference, reference, rtol=1e-9, atol=1e-3)
    dcm = load_dcm(dcm_path)
    np.testing.assert_allclose(result.response, apply(dcm, response, "steady"), rtol=1e-8, atol=1e-6)
    # the compensated response follows the true acceleration far better than the raw one
    raw_error = np.max(np.abs(response - 0.5 - reference))
    comp_error = np.max(np.abs(result.response - 0.5 - reference))
    assert comp_error < 0.5 * raw_error


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--poles", "0.9+,0.5"], "'0.9+' is not a complex number"),
        (["--poles", "1.2,0.5"], "outside the unit circle"),
        (["--poles", "0.9+0.1j,0.5"], "no conjugate partner"),
        (["--poles", "0.9,,0.5"], "empty pole"),
        (["--poles", "0.9,0.5", "--extra-poles", "0.4+0.1j"], "no conjugate partner"),
        (["--poles", "0.9,0.5", "--extra-poles", "0.4,0.3,0.2"], "at most 0 extra"),
    ],
)
def test_bad_poles(capsys, argv, expected):
    line = run_error(capsys, ["dcm", *argv, "--sample-interval", "1e-6", "--ratio", "2", "--damping", "0.7"])
    assert expected in line


def test_bad_model_files_and_arguments(tmp_path, capsys):
    common = ["--ratio", "2", "--damping", "0.7"]
    assert "no such file" in run_error(capsys, ["dcm", "--model", str(tmp_path / "nope.json"), *common])
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"dt": 1e-6, "den": [1, -0.5], "num": [0.5]}))
    assert "missing key 'sample_interval_s'" in run_error(capsys, ["dcm", "--model", str(wrong), *common])
    wrong.write_text(json.dumps({"sample_interval_s": 1e-6, "a": [[1, 2], [3, 4]], "b": [1]}))
    assert str(wrong) in run_error(capsys, ["dcm", "--model", str(wrong), *common])
    wrong.write_text(json.dumps({"sample_interval_s": 1e-6, "a": [1, -2.5], "b": [1]}))
    assert "outside the unit circle" in run_error(capsys, ["dcm", "--model", str(wrong), *common])
    assert "either --model" in run_error(capsys, ["dcm", *common])
    assert "--sample-interval" in run_error(capsys, ["dcm", "--poles", "0.5", *common])
    assert "damping" in run_error(capsys, ["dcm", "--poles", "0.5", "--sample-interval", "1e-6", "--ratio", "2", "--damping", "2"])


def test_compensate_errors(tmp_path, capsys):
    t = np.arange(100) * 2e-6
    rec = write_record(tmp_path / "r.csv", record_from_arrays(t, np.zeros(100), np.zeros(100)))
    dcm_path = tmp_path / "dcm.json"
    main(["dcm", "--poles", "0.9,0.5", "--sample-interval", "1e-6", "--ratio", "2", "--damping", "0.7", "-o", str(dcm_path)])
    capsys.readouterr()
    assert "resample" in run_error(capsys, ["compensate", str(rec), "--dcm", str(dcm_path), "-o", str(tmp_path / "o.csv")])
    assert "no such file" in run_error(capsys, ["compensate", str(tmp_path / "x.csv"), "--dcm", str(dcm_path), "-o", "o.csv"])
    assert "no such file" in run_error(capsys, ["compensate", str(rec), "--dcm", str(tmp_path / "x.json"), "-o", "o.csv"])


def test_console_entry_point_has_no_traceback(tmp_path):
    exe = Path(sys.executable).with_name("hopkinson")
    proc = subprocess.run(
        [str(exe), "dcm", "--poles", "0.9+", "--sample-interval", "1e-6", "--ratio", "2", "--damping", "0.7"],
        capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == "hopkinson: error: --poles: '0.9+' is not a complex number (write poles like 0.974+0.1396j)"
