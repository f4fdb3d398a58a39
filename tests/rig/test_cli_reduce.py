"""`hopkinson reduce`: raw shot files in, a record and the shock quantities out; clear errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.records import read_record
from hopkinson.analysis.reduce import write_raw_table
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.doppler_beat import raw_shot
from hopkinson.drivers.sim.shock import G_M_S2, half_sine_m_s2
from hopkinson.rig.cli.main import main
from hopkinson.rig.shotfile import RawChannel, RawShot, ShotMeta
from hopkinson.rig.shotfile_writer import write_raw_shot

DT = 1e-8
N = 120_000
TRIGGER = 20_000  # the pulse starts 200 µs into the record
GAIN, SENS = 100.0, 1.0e-8
FLAT = AccelerometerTruth(modes=(Mode(20.0e6, 0.7),))
KEYS = ("peak_velocity_m_s", "peak_acceleration_m_s2", "pulse_width_s", "delay_s", "shock_sensitivity",
        "demodulation_bandwidth_hz")


@pytest.fixture(scope="module")
def simulated():
    t = np.arange(N) * DT
    acc = half_sine_m_s2(t, 38.6e-6, 100_000 * G_M_S2, TRIGGER * DT)
    return t - TRIGGER * DT, raw_shot(acc, FLAT, DT, amp_gain=GAIN, sensitivity_v_per_m_s2=SENS,
                                      rng=np.random.default_rng(3), initial_phase_rad=2.0)


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_reduce_npz_writes_the_record_and_json(tmp_path: Path, simulated, capsys) -> None:
    time_s, s = simulated
    raw = write_raw_table(tmp_path / "raw.npz", time_s, s.doppler_v, s.response_v)
    out = tmp_path / "record.csv"
    code, stdout, stderr = run(["reduce", str(raw), "--amp-gain", str(GAIN), "--sensitivity-v-per-m-s2", str(SENS),
                                "-o", str(out), "--json"], capsys)
    assert code == 0, stderr
    result = json.loads(stdout.strip().splitlines()[-1])
    for key in KEYS:
        assert key in result
    assert result["peak_acceleration_m_s2"] == pytest.approx(100_000 * G_M_S2, rel=5e-3)
    assert result["shock_sensitivity"] == pytest.approx(1.0, rel=5e-3)
    assert result["response_unit"] == "m/s^2"
    record = read_record(out)
    assert record.response_unit == "m/s^2"  # the written record states its response's unit (issue 18)
    assert record.sample_rate_hz == pytest.approx(1e6)
    assert record.time_s[np.argmax(record.reference)] == pytest.approx(19.3e-6, abs=1.5e-6)  # trigger = 0
    # The peak is read between the samples (a polynomial over its lobe), not the largest sample:
    # within 0.1 % of the record's largest sample and of the simulated truth, 100 000 g.
    assert np.max(record.reference) == pytest.approx(result["peak_acceleration_m_s2"], rel=1e-3)
    assert result["peak_acceleration_m_s2"] == pytest.approx(100_000 * G_M_S2, rel=1e-3)


def test_reduce_csv_with_options_and_text_output(tmp_path: Path, simulated, capsys) -> None:
    time_s, s = simulated
    raw = write_raw_table(tmp_path / "raw.csv", time_s, s.doppler_v, s.response_v)
    out = tmp_path / "record.npz"
    code, stdout, stderr = run(["reduce", str(raw), "--sample-rate", "2e6", "--orders", "1,-1", "--grating-pitch-m",
                                "2e-6", "--bandwidth-hz", "150e3", "-o", str(out)], capsys)
    assert code == 0, stderr
    assert "peak acceleration" in stdout and "150 kHz" in stdout
    record = read_record(out)
    assert record.sample_rate_hz == pytest.approx(2e6)
    assert np.max(record.reference) == pytest.approx(100_000 * G_M_S2, rel=5e-3)


def test_reduce_hdf5_shot_file_takes_its_settings(tmp_path: Path, simulated, capsys) -> None:
    time_s, s = simulated
    channels = {}
    for name, volts in (("doppler", s.doppler_v), ("response", s.response_v)):
        scale = float(np.max(np.abs(volts))) / 30000.0
        channels[name] = RawChannel(np.round(volts / scale).astype(np.int16), scale, 0.0)
    meta = ShotMeta(operator="test", accelerometer_model="AYZ-3", accelerometer_serial="1", pressure_bar=2.0,
                    projectile=3, config={"analysis": {"grating_pitch_m": 2e-6, "orders": [1, -1],
                                                       "sensitivity_v_per_m_s2": SENS},
                                          "amplifier": {"gain": GAIN}})
    shot_file = write_raw_shot(tmp_path / "shot.h5", RawShot(channels, DT, TRIGGER), meta)
    out = tmp_path / "record.csv"
    code, stdout, stderr = run(["reduce", str(shot_file), "-o", str(out), "--json"], capsys)
    assert code == 0, stderr
    result = json.loads(stdout)
    assert result["response_unit"] == "m/s^2"  # gain and sensitivity came from the shot file
    assert result["shock_sensitivity"] == pytest.approx(1.0, rel=5e-3)
    assert result["onset_time_s"] == pytest.approx(0.0, abs=3e-6)  # times count from the trigger


def test_bad_inputs_are_one_line_and_exit_2(tmp_path: Path, simulated, capsys) -> None:
    time_s, s = simulated
    cases = []
    cases.append((["reduce", str(tmp_path / "missing.npz"), "-o", str(tmp_path / "o.csv")], "no such file"))
    (tmp_path / "raw.txt").write_text("1,2,3\n")
    cases.append((["reduce", str(tmp_path / "raw.txt"), "-o", str(tmp_path / "o.csv")], "unknown raw shot format"))
    noise = write_raw_table(tmp_path / "noise.npz", time_s, np.random.default_rng(0).normal(0, 0.01, N), s.response_v)
    cases.append((["reduce", str(noise), "-o", str(tmp_path / "o.csv")], "no Doppler beat"))
    # (A table file carries no digitizer full scale, so clipping is not judged from it: never
    # from the record's own extremes. The analysis refuses samples at a given full scale:
    # tests/analysis/test_reduce.py; the rig judges a shot from its full-scale codes.)
    slow = write_raw_table(tmp_path / "slow.npz", time_s[::100], s.doppler_v[::100], s.response_v[::100])
    cases.append((["reduce", str(slow), "-o", str(tmp_path / "o.csv")], "sampled at 1 MS/s"))
    aliased = write_raw_table(tmp_path / "aliased.npz", time_s[::2], s.doppler_v[::2], s.response_v[::2])
    cases.append((["reduce", str(aliased), "-o", str(tmp_path / "o.csv")], "aliased"))  # 24 MHz at 50 MS/s
    short = write_raw_table(tmp_path / "short.npz", time_s[:2000], s.doppler_v[:2000], s.response_v[:2000])
    cases.append((["reduce", str(short), "-o", str(tmp_path / "o.csv")], "only 2000 samples"))
    raw = write_raw_table(tmp_path / "raw.npz", time_s, s.doppler_v, s.response_v)
    cases.append((["reduce", str(raw), "--orders", "1", "-o", str(tmp_path / "o.csv")], "--orders"))
    for argv, message in cases:
        code, stdout, stderr = run(argv, capsys)
        assert code == 2, (argv, stderr)
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0], (argv, stderr)
        assert "Traceback" not in stderr


def test_console_command_runs(tmp_path: Path, simulated) -> None:
    time_s, s = simulated
    raw = write_raw_table(tmp_path / "raw.npz", time_s, s.doppler_v, s.response_v)
    done = subprocess.run([sys.executable, "-m", "hopkinson", "reduce", str(raw), "-o", str(tmp_path / "r.csv"),
                           "--json"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["demodulation_bandwidth_hz"] > 0


def test_reduce_never_writes_over_its_input_or_a_shot_file_and_refuses_bad_numbers(
        tmp_path: Path, simulated, capsys) -> None:
    time_s, s = simulated
    raw = write_raw_table(tmp_path / "raw.csv", time_s[:4000], s.doppler_v[:4000], s.response_v[:4000])
    before = raw.read_bytes()
    shot = tmp_path / "shot.h5"
    shot.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(64))
    cases = [(["reduce", str(raw), "-o", str(raw)], "input"),
             (["reduce", str(raw), "-o", str(shot)], "shot file"),
             (["reduce", str(raw), "--amp-gain", "inf", "-o", str(tmp_path / "o.csv")], "--amp-gain"),
             (["reduce", str(raw), "--grating-pitch-m", "1e300", "-o", str(tmp_path / "o.csv")], "--grating-pitch-m"),
             (["reduce", str(raw), "--sample-rate", "nan", "-o", str(tmp_path / "o.csv")], "--sample-rate"),
             (["reduce", str(raw), "--bandwidth-hz", "-5", "-o", str(tmp_path / "o.csv")], "--bandwidth-hz")]
    for argv, message in cases:
        code, stdout, stderr = run(argv, capsys)
        assert code == 2, (argv, stderr)
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0] and "Traceback" not in stderr, (argv, stderr)
    assert raw.read_bytes() == before and shot.read_bytes().startswith(b"\x89HDF")
    assert not (tmp_path / "o.csv").exists()


def test_clipping_is_judged_against_the_digitizers_full_scale(tmp_path: Path, simulated, capsys) -> None:
    """A shot file's channels carry their digitizer's full-scale codes: `reduce` judges clipping
    against them (as the rig does); a table gets them from --full-scale-v."""
    time_s, s = simulated
    scale = float(np.max(np.abs(s.response_v))) / 30000.0  # the pulse's top at code 30000 of ±32767
    response = np.round(s.response_v / scale).astype(np.int16)
    doppler_scale = float(np.max(np.abs(s.doppler_v))) / 30000.0
    doppler = RawChannel(np.round(s.doppler_v / doppler_scale).astype(np.int16), doppler_scale, 0.0,
                         (-32768.0, 32767.0))
    meta = ShotMeta(operator="t", accelerometer_model="M", accelerometer_serial="1", pressure_bar=2.0, projectile=3)

    def shot(name: str, codes: np.ndarray) -> Path:
        channels = {"doppler": doppler, "response": RawChannel(codes, scale, 0.0, (-32768.0, 32767.0))}
        return write_raw_shot(tmp_path / name, RawShot(channels, DT, TRIGGER), meta)

    code, _, stderr = run(["reduce", str(shot("ok.h5", response)), "-o", str(tmp_path / "ok.csv")], capsys)
    assert code == 0, stderr  # below the full scale: reduced
    railed = response.copy()
    railed[np.argmax(response):][:7] = 32767  # seven samples on the top code
    code, _, stderr = run(["reduce", str(shot("railed.h5", railed)), "-o", str(tmp_path / "r.csv")], capsys)
    assert code == 2 and stderr.count("\n") == 1, stderr
    top = 32767 * scale
    assert f"response channel: clipped: 7 samples at the digitizer's full scale ({-32768 * scale:.4g} .. {top:.4g} V)" \
        in stderr
    assert not (tmp_path / "r.csv").exists()

    table = write_raw_table(tmp_path / "raw.npz", time_s, s.doppler_v, s.response_v)
    peak = float(np.max(s.response_v))
    code, _, stderr = run(["reduce", str(table), "--full-scale-v", "20", "--full-scale-v", f"response={-peak},{peak}",
                           "-o", str(tmp_path / "t.csv")], capsys)
    assert code == 2 and "response channel: clipped: 1 samples" in stderr, stderr  # its peak is at the given top
    code, _, stderr = run(["reduce", str(table), "--full-scale-v", f"{2 * peak}", "-o", str(tmp_path / "t.csv")],
                          capsys)
    assert code == 0, stderr
    for bad in ("x", "1,2,3", "5,-5", "inf", "velocity=10", "0"):
        code, _, stderr = run(["reduce", str(table), "--full-scale-v", bad, "-o", str(tmp_path / "b.csv")], capsys)
        assert code == 2 and stderr.count("\n") == 1 and "--full-scale-v" in stderr, (bad, stderr)
