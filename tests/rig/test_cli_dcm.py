"""`hopkinson dcm` and `hopkinson compensate`: the paper through the command line, files
in and out, and one clear line with exit 2 for every kind of bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.dcm import load_dcm
from hopkinson.analysis.dcm_stream import apply
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


def run_text(capsys, argv: list[str]) -> str:
    assert main(argv) == 0
    return capsys.readouterr().out


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


def shock_record(tmp_path: Path, dt: float = 1e-6, n: int = 3000, start_s: float = 200e-6):
    """A 27 kHz, ζ = 0.05 sensor hit by the paper's 38.6 µs half-sine, with a zero offset; its
    exact model and the record's path."""
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),))
    b, a = truth.discrete_tf(dt)
    t = np.arange(n) * dt
    reference = half_sine_m_s2(t, 38.6e-6, 1e6, start_s=start_s)
    response = truth.respond(reference, dt) + 0.5
    path = write_record(tmp_path / "shot.npz", record_from_arrays(t, reference, response))
    return DiscreteModel(dt, a, b), path, reference, response


def test_compensate_streams_the_response_aligned_with_the_reference(tmp_path, capsys):
    model, rec_path, reference, response = shock_record(tmp_path)
    model_path = tmp_path / "m.json"
    model_path.write_text(json.dumps({"model": model.to_dict(), "supported_band_hz": [0.0, 36_000.0]}))
    dcm_path = tmp_path / "dcm.json"
    design = run_json(capsys, ["dcm", "--model", str(model_path), "--json", "-o", str(dcm_path)])
    # the band limit's ±5 % edge at the top of the supported band (36 kHz): the 4th-order
    # Butterworth magnitude's cut-off 36 / 0.758 kHz
    assert design["dcm"]["band_limit_hz"] == pytest.approx(36_000.0 / (1 / 0.95**2 - 1) ** 0.125, rel=1e-9)
    assert design["dcm"]["latency_s"] > 0
    out = tmp_path / "out.csv"
    info = run_json(capsys, ["compensate", str(rec_path), "--dcm", str(dcm_path), "-o", str(out),
                             "--block-samples", "257", "--json"])
    assert info["blocks"] == 12 and info["initial"] == "steady" and "reference" in info["what"]
    assert info["latency_removed"] and info["latency_s"] == pytest.approx(design["dcm"]["latency_s"])
    assert info["resampled"] is None
    result = read_record(out)
    np.testing.assert_allclose(result.reference, reference, rtol=1e-9, atol=1e-3)
    dcm = load_dcm(dcm_path)
    np.testing.assert_allclose(result.response, apply(dcm, response, "steady", align=True), rtol=1e-8, atol=1e-6)
    # aligned: the compensated pulse peaks where the reference does (within a sample), and it
    # follows the true acceleration far better than the raw response
    assert abs(int(np.argmax(result.response)) - int(np.argmax(reference))) <= 1
    raw_error = np.max(np.abs(response - 0.5 - reference))
    comp_error = np.max(np.abs(result.response - 0.5 - reference))
    assert comp_error < 0.2 * raw_error
    # --causal keeps the latency: the plain causal filter, its peak later by about the latency
    causal = tmp_path / "causal.npz"
    info = run_json(capsys, ["compensate", str(rec_path), "--dcm", str(dcm_path), "-o", str(causal), "--causal",
                             "--json"])
    assert not info["latency_removed"]
    lagging = read_record(causal).response
    np.testing.assert_allclose(lagging, apply(dcm, response, "steady"), rtol=1e-8, atol=1e-6)
    lag = int(np.argmax(lagging)) - int(np.argmax(reference))
    assert lag == pytest.approx(dcm.latency_s / 1e-6, abs=1.5)


def test_compensate_brings_a_record_to_the_dcm_rate_and_says_so(tmp_path, capsys):
    model, rec_path, reference, _ = shock_record(tmp_path)
    model_path = tmp_path / "m.json"
    model_path.write_text(json.dumps({"model": model.to_dict(), "supported_band_hz": [0.0, 36_000.0]}))
    dcm_path = tmp_path / "dcm.json"
    run_json(capsys, ["dcm", "--model", str(model_path), "--json", "-o", str(dcm_path)])
    # the same shot recorded at 4 MS/s
    fine_model, fine_path, fine_reference, _ = shock_record(tmp_path / "..", dt=0.25e-6, n=12_000)
    out = tmp_path / "out.csv"
    info = run_json(capsys, ["compensate", str(fine_path), "--dcm", str(dcm_path), "-o", str(out), "--json"])
    assert "from 4e+06 Hz to 1e+06 Hz" in info["resampled"] and "resampled" in info["what"]
    result = read_record(out)
    assert result.sample_interval_s == pytest.approx(1e-6) and result.n_samples == 3000
    assert np.max(np.abs(result.response - 0.5 - reference)) < 0.2 * np.max(reference)


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


def test_auto_is_the_default_and_reports_the_widening(tmp_path, capsys):
    model, rec_path, _, _ = shock_record(tmp_path)
    model_path = tmp_path / "m.json"
    model_path.write_text(json.dumps({"model": model.to_dict(), "supported_band_hz": [0.0, 36_000.0]}))
    result = run_json(capsys, ["dcm", "--model", str(model_path), "--record", str(rec_path), "--json"])
    dcm = result["dcm"]
    # with the record: sized to its pulse (analysis.dcm_ratio), no widening aimed for
    assert dcm["sized_to"] == "pulse" and dcm["target_widening"] is None
    assert "sized to the pulse" in dcm["widening_note"] and abs(dcm["predicted_peak_error_pct"]) < 1.0
    assert result["compensated_fbsd_hz"]["5"] == pytest.approx(dcm["reached_widening"] * result["fbsd_hz"]["5"])
    assert 0 < dcm["noise_gain"] <= dcm["noise_gain_limit"] == 4.0
    # checked on its own shot: far better than the raw response, so recommended
    check = dcm["check"]
    assert check["rms_error_pct"]["compensated"] < 0.2 * check["rms_error_pct"]["uncompensated"]
    assert dcm["recommended"] is True and dcm["not_recommended_reason"] is None
    # without the record: sized to the band the model file says the shot supports
    band = run_json(capsys, ["dcm", "--model", str(model_path), "--json"])["dcm"]
    assert band["sized_to"] == "band" and "no pulse to size it to" in band["widening_note"]
    # asking for more than the band limit allows: reached, aimed for, and why not
    text = run_text(capsys, ["dcm", "--model", str(model_path), "--widening", "10"])
    assert "aimed for ×10, reached ×" in text and "±5 % up to 36 kHz" in text and "caps it" in text


def test_dcm_file_is_written_atomically_and_never_over_an_input(tmp_path, capsys):
    model_path = write_model(tmp_path / "model.json", table1_model())
    before = model_path.read_text()
    line = run_error(capsys, ["dcm", "--model", str(model_path), "-o", str(model_path)])
    assert "is the input" in line and model_path.read_text() == before
    assert "does not exist" in run_error(capsys, ["dcm", "--model", str(model_path), "-o", str(tmp_path / "no" / "d.json")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json"]  # nothing half-written


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--poles", "0,0", "--sample-interval", "1e-6"], "nothing to compensate"),
        (["--poles=-0.98,0.5", "--sample-interval", "1e-6", "--ratio", "2"], None),
        (["--poles", "0.9,0.5", "--sample-interval", "nan"], "--sample-interval"),
        (["--poles", "0.9,0.5", "--sample-interval", "1e-6", "--ratio", "-3"], "--ratio"),
        (["--poles", "0.9,0.5", "--sample-interval", "1e-6", "--band-limit", "fast"], "--band-limit"),
    ],
)
def test_degenerate_designs_are_one_line_errors(capsys, argv, expected):
    if expected is None:  # a Nyquist artefact among the poles is left alone, the rest designed
        result = run_json(capsys, ["dcm", *argv, "--json"])
        assert result["dcm"]["zeros"] == [[0.5, 0.0]]
        assert "Nyquist" in result["dcm"]["design"]["skipped_poles"][0]["reason"]
        return
    assert expected in run_error(capsys, ["dcm", *argv])


def test_compensate_errors(tmp_path, capsys):
    t = np.arange(100) * 1e-6
    rec = write_record(tmp_path / "r.csv", record_from_arrays(t, np.zeros(100), np.ones(100)))
    dcm_path = tmp_path / "dcm.json"
    main(["dcm", "--poles", "0.9,0.5", "--sample-interval", "1e-6", "--ratio", "2", "--damping", "0.7", "-o", str(dcm_path)])
    capsys.readouterr()
    out = tmp_path / "o.csv"
    assert "no such file" in run_error(capsys, ["compensate", str(tmp_path / "x.csv"), "--dcm", str(dcm_path), "-o", str(out)])
    assert "no such file" in run_error(capsys, ["compensate", str(rec), "--dcm", str(tmp_path / "x.json"), "-o", str(out)])
    # never over an input or a shot file
    assert "is the input" in run_error(capsys, ["compensate", str(rec), "--dcm", str(dcm_path), "-o", str(rec)])
    assert "is the input" in run_error(capsys, ["compensate", str(rec), "--dcm", str(dcm_path), "-o", str(dcm_path)])
    shot = tmp_path / "shot.h5"
    shot.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(64))
    assert "shot file" in run_error(capsys, ["compensate", str(rec), "--dcm", str(dcm_path), "-o", str(shot)])
    # a DCM whose output overflows is an error, and leaves no output behind
    huge = tmp_path / "huge.json"
    huge.write_text(json.dumps({"sample_interval_s": 1e-6, "zeros": [[0.5, 0]], "poles": [[0.2, 0]], "gain": 1e308}))
    assert "not a finite number" in run_error(capsys, ["compensate", str(rec), "--dcm", str(huge), "-o", str(out)])
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["dcm.json", "huge.json", "r.csv", "shot.h5"]
    huge.write_text(json.dumps({"sample_interval_s": 1e-6, "zeros": [[-0.9, 0], [-0.9, 0]],
                                "poles": [[0.2, 0], [0.1, 0]], "gain": 1e308}))
    assert "not finite" in run_error(capsys, ["compensate", str(rec), "--dcm", str(huge), "-o", str(out)])
    # a DCM its shot marked not recommended is refused unless forced
    data = json.loads(dcm_path.read_text())
    data["dcm"].update(recommended=False, not_recommended_reason="it raises the RMS error")
    worse = tmp_path / "worse.json"
    worse.write_text(json.dumps(data))
    line = run_error(capsys, ["compensate", str(rec), "--dcm", str(worse), "-o", str(out)])
    assert "not recommended (it raises the RMS error)" in line and "--force" in line
    assert main(["compensate", str(rec), "--dcm", str(worse), "-o", str(out), "--force"]) == 0


def test_console_entry_point_has_no_traceback(tmp_path):
    exe = Path(sys.executable).with_name("hopkinson")
    proc = subprocess.run(
        [str(exe), "dcm", "--poles", "0.9+", "--sample-interval", "1e-6", "--ratio", "2", "--damping", "0.7"],
        capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == "hopkinson: error: --poles: '0.9+' is not a complex number (write poles like 0.974+0.1396j)"


def test_dcm_of_an_identified_model_with_its_record_is_the_shot_analysis_dcm(tmp_path, capsys):
    """identify -o, then dcm --model --record: the same design (poles cancelled, band limit from
    the excitation and the response's noise, ratio, latency) and check as the shot analysis."""
    from hopkinson.analysis.compensation import compensate_shot
    from hopkinson.analysis.identify import identify
    from hopkinson.analysis.options import AnalysisOptions
    from hopkinson.drivers.sim.accelerometer import white_noise

    dt, n = 1e-6, 4000
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05), Mode(95_000.0, 0.02)), sensitivity=2e-3)
    t = np.arange(n) * dt
    rng = np.random.default_rng(4)
    reference = half_sine_m_s2(t, 38.6e-6, 4e5, start_s=400e-6)
    response = truth.respond(reference, dt)
    record = record_from_arrays(t, reference + white_noise(reference, 40, rng), response + white_noise(response, 40, rng))
    rec_path = write_record(tmp_path / "shot.csv", record)
    model_path = tmp_path / "model.json"
    assert main(["identify", str(rec_path), "-o", str(model_path), "--json", "--draws", "50"]) == 0  # (the DCM's test)
    capsys.readouterr()
    result = run_json(capsys, ["dcm", "--model", str(model_path), "--record", str(rec_path), "--json"])
    shot = compensate_shot(identify(read_record(rec_path)), read_record(rec_path), AnalysisOptions())
    assert result["dcm"]["band_limit_hz"] == pytest.approx(shot.design.band_limit.cutoff_hz, rel=1e-6)
    assert result["dcm"]["design"]["ratio"] == pytest.approx(shot.design.dcm.design["ratio"], rel=1e-3)
    np.testing.assert_allclose(result["dcm"]["num"], shot.design.dcm.num, rtol=1e-4)
    assert result["dcm"]["latency_s"] == pytest.approx(shot.design.latency_s, rel=1e-3)
    assert result["dcm"]["check"]["rms_error_pct"]["compensated"] == pytest.approx(shot.check.rms_error_pct[1], rel=1e-3)
    assert result["dcm"]["recommended"] is True


def test_a_dcm_file_edited_in_one_form_only_is_refused(tmp_path, capsys):
    # issue 18: a DCM JSON with zeros/poles/gain ignored edited num/den without saying so
    model, rec_path, _, _ = shock_record(tmp_path)
    model_path = tmp_path / "m.json"
    model_path.write_text(json.dumps({"model": model.to_dict(), "supported_band_hz": [0.0, 36_000.0]}))
    dcm_path = tmp_path / "dcm.json"
    run_json(capsys, ["dcm", "--model", str(model_path), "--json", "-o", str(dcm_path)])
    data = json.loads(dcm_path.read_text())
    dcm = data.get("dcm", data)
    assert "num" in dcm and "zeros" in dcm  # the file holds both forms
    dcm["num"] = [2.0 * c for c in dcm["num"]]  # edited by hand in one form
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(data))
    line = run_error(capsys, ["compensate", str(rec_path), "--dcm", str(edited), "-o", str(tmp_path / "out.csv")])
    assert f"{edited}: num is not the filter its zeros, poles and gain give" in line
