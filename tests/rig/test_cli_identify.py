"""`hopkinson identify`: JSON contract, model file for `hopkinson dcm`, summary, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.model import load_model
from hopkinson.analysis.records import Record, write_record
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode, white_noise
from hopkinson.drivers.sim.shock import half_sine_m_s2
from hopkinson.rig.cli.main import main

T = 1e-6
TRUTH = AccelerometerTruth(modes=(Mode(27_000.0, 0.05), Mode(70_000.0, 0.03)))


def _record(n: int = 20_000, dt: float = T, seed: int = 0) -> Record:
    u = half_sine_m_s2(np.arange(n) * dt, 10e-6, 1.0, 100e-6)
    rng = np.random.default_rng(seed)
    y = TRUTH.respond(u, dt)
    return Record(dt, u + white_noise(u, 40.0, rng), y + white_noise(y, 40.0, rng))


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("identify")
    record = _record()
    out = {"csv": write_record(folder / "shot.csv", record), "npz": write_record(folder / "shot.npz", record)}
    out["folder"] = folder
    return out


def _run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _relative_pole_errors(poles: list[list[float]]) -> np.ndarray:
    est = np.log(np.array([complex(*p) for p in poles])) / T
    true = np.log(TRUTH.discrete_poles(T)) / T
    return np.array([np.min(np.abs(est - s)) / abs(s) for s in true])


def test_json_has_the_model_fields_fbsd_and_pole_analysis(files, capsys) -> None:
    code, out, err = _run(["identify", str(files["csv"]), "--json", "--draws", "50"], capsys)
    assert code == 0, err
    data = json.loads(out)
    for key in ("sample_interval_s", "order", "a", "b", "poles", "zeros", "dc_gain", "loss_by_order",
                "fbsd_hz", "pole_analysis", "fit_percent", "delay_samples", "warnings"):
        assert key in data, key
    assert data["order"] == 4
    assert data["sample_interval_s"] == pytest.approx(T)
    assert np.max(_relative_pole_errors(data["poles"])) < 1e-3
    assert set(data["fbsd_hz"]) == {"5", "10"} and 0 < data["fbsd_hz"]["5"] < data["fbsd_hz"]["10"]
    assert len(data["pole_analysis"]) == 4
    assert all({"pole", "response_time_samples", "ratio"} <= set(row) for row in data["pole_analysis"])
    assert data["a"][0] == 1.0 and len(data["b"]) == 5


def test_model_file_is_read_by_load_model_and_hopkinson_dcm(files, capsys) -> None:
    model_path = files["folder"] / "model.json"
    code, out, err = _run(["identify", str(files["npz"]), "-o", str(model_path), "--draws", "50"], capsys)
    assert code == 0, err
    assert "order 4" in out and "FBSD" in out and "kHz" in out and "fit" in out
    written = json.loads(model_path.read_text())
    model = load_model(model_path)
    assert np.allclose(model.a, written["a"]) and np.allclose(model.b, written["b"])
    assert model.order == 4
    code, out, err = _run(["dcm", "--model", str(model_path), "--ratio", "5", "--damping", "0.707", "--json"], capsys)
    assert code == 0, err
    assert len(json.loads(out)["pole_analysis"]) == 4


def test_order_and_sample_rate_options(files, tmp_path, capsys) -> None:
    # (the options choose the model and the rate: no uncertainty needed to see them)
    code, out, _ = _run(["identify", str(files["csv"]), "--order", "2", "--json", "--no-uncertainty"], capsys)
    assert code == 0
    assert json.loads(out)["order"] == 2
    fast = write_record(tmp_path / "fast.npz", _record(n=100_000, dt=1e-7))
    code, out, err = _run(["identify", str(fast), "--json", "--no-uncertainty"], capsys)
    assert code == 0, err
    assert json.loads(out)["sample_interval_s"] == pytest.approx(1e-6)  # resampled to 1 MS/s
    code, out, err = _run(["identify", str(fast), "--sample-rate", "2e6", "--max-order", "6", "--json",
                           "--no-uncertainty"], capsys)
    assert code == 0, err
    assert json.loads(out)["sample_interval_s"] == pytest.approx(5e-7)


def _one_line_error(code: int, out: str, err: str) -> str:
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def test_bad_records_are_one_clear_line(tmp_path, capsys) -> None:
    missing = tmp_path / "missing.csv"
    missing.write_text("time_s,reference\n0,1\n1e-6,2\n")
    line = _one_line_error(*_run(["identify", str(missing)], capsys))
    assert "missing.csv" in line and "response" in line

    record = _record(n=4000)
    nan = tmp_path / "nan.csv"
    write_record(nan, record)
    rows = nan.read_text().splitlines()
    rows[50] = rows[50].rsplit(",", 1)[0] + ",nan"
    nan.write_text("\n".join(rows) + "\n")
    line = _one_line_error(*_run(["identify", str(nan)], capsys))
    assert "nan.csv" in line and "NaN" in line

    short = write_record(tmp_path / "short.csv", Record(T, record.reference[:200], record.response[:200]))
    line = _one_line_error(*_run(["identify", str(short), "--order", "12"], capsys))
    assert "short.csv" in line and "too short" in line

    line = _one_line_error(*_run(["identify", str(tmp_path / "absent.csv")], capsys))
    assert "absent.csv" in line

    line = _one_line_error(*_run(["identify", str(short), "--max-order", "0"], capsys))
    assert "--max-order" in line


def test_unstable_model_is_one_clear_line(tmp_path, capsys) -> None:
    from scipy import signal

    u = half_sine_m_s2(np.arange(3000) * T, 10e-6, 1.0, 100e-6)
    a = np.poly([1.0005 * np.exp(0.1j), 1.0005 * np.exp(-0.1j)])  # a growing oscillation
    y = signal.lfilter([0.0, 0.01, 0.01], a, u)
    y = y + white_noise(y, 40.0, np.random.default_rng(0))
    path = write_record(tmp_path / "growing.csv", Record(T, u, y))
    line = _one_line_error(*_run(["identify", str(path), "--order", "2"], capsys))
    assert "growing.csv" in line and "unstable" in line


# --- uncertainty, safe outputs, bad numbers -----------------------------------------------------


def test_uncertainty_follows_the_json_contract_and_the_text_shows_value_plus_minus_u(files, capsys) -> None:
    code, out, err = _run(["identify", str(files["csv"]), "--json", "--draws", "60", "--seed", "4"], capsys)
    assert code == 0, err
    data = json.loads(out)
    unc = data["uncertainty"]
    assert unc["draws"] == 60 and unc["coverage_probability"] == 0.95 and "Monte Carlo" in unc["method"]
    figures = {"dc_gain": (unc["dc_gain"], data["dc_gain"]),
               "f_n": (unc["main_mode"]["natural_frequency_hz"], data["main_mode"]["natural_frequency_hz"]),
               "zeta": (unc["main_mode"]["damping_ratio"], data["main_mode"]["damping_ratio"]),
               "fbsd5": (unc["fbsd_hz"]["5"], data["fbsd_hz"]["5"]),
               "fbsd10": (unc["fbsd_hz"]["10"], data["fbsd_hz"]["10"]),
               "shock": (unc["shock_sensitivity"], unc["shock_sensitivity"]["value"])}
    for name, (figure, reported) in figures.items():
        assert set(figure) == {"value", "u", "interval"}, name
        assert figure["value"] == reported, name  # `value` is the figure reported elsewhere
        lo, hi = figure["interval"]
        assert figure["u"] > 0 and lo < hi, name
    # The main mode is the truth's 27 kHz pair, and its interval is tight around it.
    assert unc["main_mode"]["natural_frequency_hz"]["interval"][0] < 27_000 * 1.001
    assert unc["main_mode"]["natural_frequency_hz"]["interval"][1] > 27_000 * 0.999
    sources = [b["source"] for b in unc["budget"]]
    assert {"response noise", "reference noise", "order choice", "grating pitch", "amplifier gain"} <= set(sources)
    assert all(set(b) >= {"source", "u_rel"} for b in unc["budget"])

    code, out, err = _run(["identify", str(files["csv"]), "--draws", "60", "--seed", "4"], capsys)
    assert code == 0, err
    assert "f_n = 26.99" in out and "±" in out.split("f_n =")[1].split("\n")[0]
    assert "DC gain" in out and "±" in out.split("DC gain")[1].split("\n")[0]
    assert "±5 % up to" in out and "±" in out.split("±5 % up to")[1].split("kHz")[0]


def test_no_uncertainty_keeps_the_values_and_says_so(files, capsys) -> None:
    code, out, err = _run(["identify", str(files["csv"]), "--json", "--no-uncertainty"], capsys)
    assert code == 0, err
    data = json.loads(out)
    assert data["uncertainty"] is None and data["order"] == 4
    assert any("uncertainty switched off" in w for w in data["warnings"])


def test_outputs_never_overwrite_the_input_or_a_shot_file(files, tmp_path, capsys) -> None:
    record = files["csv"]
    before = record.read_bytes()
    line = _one_line_error(*_run(["identify", str(record), "-o", str(record), "--no-uncertainty"], capsys))
    assert "input" in line and record.read_bytes() == before
    shot = tmp_path / "shot.h5"
    shot.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(64))  # an HDF5 signature: a shot file
    line = _one_line_error(*_run(["identify", str(record), "-o", str(shot), "--no-uncertainty"], capsys))
    assert "shot file" in line and shot.read_bytes().startswith(b"\x89HDF")
    line = _one_line_error(*_run(["identify", str(record), "-o", str(tmp_path / "no" / "m.json")], capsys))
    assert "does not exist" in line
    out = tmp_path / "model.json"
    out.write_text("old")
    code, _, err = _run(["identify", str(record), "-o", str(out), "--no-uncertainty"], capsys)
    assert code == 0, err
    assert json.loads(out.read_text())["order"] == 4  # replaced whole
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary left


@pytest.mark.parametrize(("flag", "value"), [("--sample-rate", "inf"), ("--sample-rate", "1e300"),
                                             ("--sample-rate", "nan"), ("--draws", "3"), ("--order", "1000")])
def test_bad_numbers_are_one_line(files, capsys, flag: str, value: str) -> None:
    line = _one_line_error(*_run(["identify", str(files["csv"]), flag, value], capsys))
    assert flag in line


def test_the_command_runs_blas_on_one_thread_and_identify_loads_no_scipy(files) -> None:
    """The `hopkinson` command sets the BLAS thread variables before NumPy loads (a value the
    user set is kept), and `identify` without a sine imports no SciPy (its start-up is part of
    the command's time: benchmarks/bench_identify.py)."""
    import os
    import subprocess
    import sys

    probe = ("import os, sys; import hopkinson.rig.cli.main as m; loaded = 'numpy' in sys.modules; "
             f"code = m.main(['identify', {str(files['npz'])!r}, '--no-uncertainty', '--json']); "
             "print(loaded, os.environ['OPENBLAS_NUM_THREADS'], os.environ['MKL_NUM_THREADS'], "
             "any(k == 'scipy' or k.startswith('scipy.') for k in sys.modules), code, file=sys.stderr)")
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True)
    assert done.stderr.split()[-5:] == ["False", "1", "1", "False", "0"], done.stderr
    env["OPENBLAS_NUM_THREADS"] = "2"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True)
    assert done.stderr.split()[-5:-3] == ["False", "2"], done.stderr
