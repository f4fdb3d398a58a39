"""A quadrature interferometer and a second sensor, end to end: `hopkinson shot --sim` on a
simulated rig whose sim.toml turns both on (the quadrature photodetector on channel 3, the second
accelerometer on channel 4), over the real protocols; the shot file, the analysis of both
sensors and the report are judged against the simulator's truth recorded with the shot; and
`hopkinson reduce` on a raw table with a doppler_quadrature column."""

from __future__ import annotations

import dataclasses
import io
import json
import math
import re
import shutil
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from hopkinson.analysis.reduce import reduce_raw
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.doppler_beat import QuadratureOutput, pm_beat
from hopkinson.drivers.sim.shock import G_M_S2, half_sine_m_s2, velocity_m_s
from hopkinson.drivers.sim.shot_truth import accelerometer_truth
from hopkinson.reports.pages import report_pages
from hopkinson.reports.tables import SENSITIVITY_ROW, results_rows
from hopkinson.reports.writers import write_pngs, write_report
from hopkinson.rig.cli.main import main
from hopkinson.rig.config import load_rig_config, load_sim_config
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.report_data import shot_report
from hopkinson.rig.shotfile import read_shot, sensor_records

REPO = Path(__file__).resolve().parents[2]
SIM_TOML = """[world]
time_scale = 100.0
[world.signals]
quadrature = true
[world.accelerometer_2]
enabled = true
"""
# The reference acceleration against the simulated truth over the pulse, as a fraction of the
# peak: the same tolerance for the quadrature pair and for the PM beat of the same shot.
RMS_TOL, PEAK_TOL = 5e-3, 3e-3
# What the second sensor's data sheet states, in the rig config's [analysis] (rig.shot.SECOND_SENSOR_STATED)
SECOND_STATED = {"transverse_sensitivity_2_rel": 0.02, "asymmetry_bound_2_rel": 0.04}


@pytest.fixture(scope="module")
def fired(tmp_path_factory: pytest.TempPathFactory) -> SimpleNamespace:
    """One shot (2 bar, ~50 000 g), analysed with a 50-draw uncertainty for both sensors; the
    rig config states the second sensor's own transverse sensitivity and asymmetry bound
    (SECOND_STATED), the first sensor's are the rig's [uncertainty] values."""
    folder = tmp_path_factory.mktemp("quadrature-shot")
    text = (REPO / "config" / "rig-sim.toml").read_text(encoding="utf-8")
    for key, value in {"evacuate_s": 2.0, "charge_s": 3.0, "arm_s": 1.0, "capture_s": 2.0, "safe_s": 3.0}.items():
        text, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
        assert n == 1, key
    text, n = re.subn(r"^(sensitivity_2_v_per_m_s2 = .*)$",
                      lambda m: m.group(1) + "".join(f"\n{k} = {v}" for k, v in SECOND_STATED.items()), text, flags=re.M)
    assert n == 1
    (folder / "rig.toml").write_text(text, encoding="utf-8")
    (folder / "sim.toml").write_text(SIM_TOML, encoding="utf-8")
    out, err = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as mp:  # the private lock and runtime folders of tests/conftest.py
        mp.setenv("HOPKINSON_LOCK_DIR", str(tmp_path_factory.mktemp("locks")))
        runtime = tmp_path_factory.mktemp("runtime")
        runtime.chmod(0o700)
        mp.setenv("XDG_RUNTIME_DIR", str(runtime))
        with redirect_stdout(out), redirect_stderr(err):
            rc = main(["shot", "--sim", "--config", str(folder / "rig.toml"), "--sim-config", str(folder / "sim.toml"),
                       "--out", str(folder), "--pressure-bar", "2.0", "--yes", "--shot-name", "q1", "--draws", "50",
                       "--accelerometer-2-model", "AYZ-3", "--accelerometer-2-serial", "SN0002"])
    shot = read_shot(folder / "q1.h5")
    return SimpleNamespace(rc=rc, out=out.getvalue(), err=err.getvalue(), shot=shot, truth=shot.meta.simulated_truth)


def test_the_shot_records_four_channels_and_summarises_both_sensors(fired) -> None:
    assert fired.rc == 0 and "error" not in fired.err, fired.err
    assert set(fired.shot.raw.channels) == {"doppler", "response", "doppler_quadrature", "response_2"}
    assert fired.shot.meta.sensor_identities == {"response_2": {"model": "AYZ-3", "serial": "SN0002"}}
    assert re.search(r"^results: .*f_n 2[67]\.\d+ ± 0\.\d+ kHz.*FBSD ±5 % \d", fired.out, flags=re.M), fired.out
    assert re.search(r"^response_2: .*f_n 3[23]\.\d+ ± 0\.\d+ kHz.*FBSD ±5 % \d", fired.out, flags=re.M), fired.out


def test_each_sensors_budget_carries_what_its_own_data_sheet_states(fired) -> None:
    """The second sensor's transverse row is its own stated S_t (rig config [analysis]
    transverse_sensitivity_2_rel) times the bar's r_T over √3, its asymmetry bound its own; the
    first sensor keeps the rig's [uncertainty] values. Re-analysed from the file, the same."""
    config = load_rig_config(REPO / "config" / "rig-sim.toml")
    motion = config.uncertainty.transverse_motion_rel
    first = (config.uncertainty.transverse_sensitivity_rel, config.uncertainty.asymmetry_bound_rel)
    second = tuple(SECOND_STATED.values())  # in SENSOR_STATED's order: transverse, asymmetry
    assert first != second
    for results in (fired.shot.results, read_shot(_reanalysed(fired)).results):
        for stated, sensor in ((first, results), (second, results["sensors"]["response_2"])):
            params = sensor["params"]
            assert (params["transverse_sensitivity_rel"], params["asymmetry_bound_rel"]) == stated
            (row,) = [b for b in sensor["uncertainty"]["budget"] if b["source"].startswith("transverse sensitivity")]
            assert row["u_rel_by_figure"]["dc_gain"] == pytest.approx(stated[0] * motion / math.sqrt(3), rel=1e-9)


def _reanalysed(fired) -> Path:
    """A copy of the shot analysed again (`hopkinson analyse`: the rig config from its snapshot)."""
    copy = fired.shot.path.with_name("q1-again.h5")
    if not copy.exists():
        shutil.copyfile(fired.shot.path, copy)
        with redirect_stdout(io.StringIO()):
            assert main(["analyse", str(copy), "--draws", "50"]) == 0
    return copy


def _reference_errors(record, truth: dict, dt: float, peak_estimate: float) -> tuple[float, float]:
    """RMS error over the pulse and peak error of a record's reference against the truth."""
    reference = truth["reference"]
    t = record.time_s - truth["capture"]["pulse_start_index"] * dt  # the truth's time: 0 at the pulse start
    pulse = (t > -20e-6) & (t < truth["pulse_width_s"] + 40e-6)
    true_acc = np.interp(t, reference["time_s"], reference["acceleration_m_s2"])
    peak = truth["peak_acceleration_m_s2"]
    return (float(np.sqrt(np.mean((record.reference - true_acc)[pulse] ** 2))) / peak,
            abs(peak_estimate / peak - 1.0))


def test_quadrature_reference_is_within_the_pm_beat_tolerance_of_the_truth(fired) -> None:
    shot, truth = fired.shot, fired.truth
    reduction = shot.results["reduction"]
    assert reduction["interferometer"] == "quadrature"
    ellipse, true_ellipse = reduction["quadrature"], truth["quadrature"]
    for key in ("offset_1_v", "offset_2_v"):
        assert ellipse[key] == pytest.approx(true_ellipse[key], abs=2e-3)
    assert ellipse["amplitude_ratio"] == pytest.approx(true_ellipse["amplitude_ratio"], rel=5e-3)
    assert np.radians(ellipse["phase_error_deg"]) == pytest.approx(true_ellipse["phase_error_rad"], abs=np.radians(0.3))
    dt = shot.raw.sample_interval_s
    quadrature = _reference_errors(shot.record, truth, dt, reduction["peak_acceleration_m_s2"])
    # The PM beat of the same shot (its doppler channel alone), reduced the same way.
    pm = reduce_raw(shot.volts("doppler"), shot.volts("response"), dt)
    beat = _reference_errors(pm.record, truth, dt, pm.peak_acceleration_m_s2)
    for rms, peak in (quadrature, beat):
        assert rms < RMS_TOL and peak < PEAK_TOL, (quadrature, beat)
    assert reduction["peak_velocity_m_s"] == pytest.approx(truth["delta_velocity_m_s"], rel=1e-3)


@pytest.mark.parametrize(("role", "truth_key"), [("response", "accelerometer"), ("response_2", "accelerometer_2")])
def test_each_sensor_is_identified_as_its_own_truth(fired, role: str, truth_key: str) -> None:
    results = fired.shot.results if role == "response" else fired.shot.results["sensors"][role]
    analysis = ShotAnalysis.from_dict(results)
    true = accelerometer_truth(fired.truth, truth_key)
    dt = analysis.model.sample_interval_s
    s_true = np.log(true.discrete_poles(dt)[0]) / dt
    s_found = np.log(analysis.model.poles) / dt
    assert np.min(np.abs(s_found - s_true)) / abs(s_true) < 5e-3
    main = analysis.identification["main_mode"]
    (mode,) = fired.truth[truth_key]["modes"]
    assert main["natural_frequency_hz"] == pytest.approx(mode["natural_frequency_hz"], rel=5e-3)
    assert main["damping_ratio"] == pytest.approx(mode["damping_ratio"], rel=0.05)
    # Scaled by the rig config's gain and nominal sensitivity, which match the simulated sensor's.
    assert results["reduction"]["response_unit"] == "m/s^2"
    assert analysis.model.dc_gain == pytest.approx(1.0, rel=5e-3)
    assert results["uncertainty"]["draws"] == 50 and results["uncertainty"]["dc_gain"]["u"] > 0
    assert results["fbsd_hz"]["5"] > 0 and "check" in results["dcm"]


def test_the_shot_file_keeps_the_second_sensors_record(fired) -> None:
    shot = fired.shot
    records = sensor_records(shot)
    assert set(records) == {"response_2"} and "response_2_m_s2" in shot.derived
    analysis = ShotAnalysis.from_dict(shot.results, shot.record, records)
    second = analysis.sensors["response_2"]
    assert second.record is not None and np.array_equal(second.record.reference, shot.record.reference)
    # Its response peaks with its own resonance (33 kHz, ζ 0.03) above the first's (27 kHz, ζ 0.05).
    assert analysis.to_dict()["sensors"]["response_2"]["model"] == shot.results["sensors"]["response_2"]["model"]


def test_the_report_has_a_section_and_pages_per_sensor(fired, tmp_path: Path, artifacts_dir: Path) -> None:
    report = shot_report(fired.shot.path)
    first, second = report.shots
    assert second.label == "q1, second sensor (response_2)" and second.analysis is not None
    rows = dict(results_rows(second))
    truth_row = re.fullmatch(r"33 kHz, 0\.03: pole error (\S+) %", rows["simulated truth f_n, ζ"])
    assert truth_row is not None and float(truth_row.group(1)) < 0.5, rows["simulated truth f_n, ζ"]
    assert "× nominal = " in rows[SENSITIVITY_ROW]  # 1.0 × 1e-7 V/(m/s²)
    assert rows["model order"] == "2 (chosen by the order test)"  # the stored "knee" in words
    pages = report_pages(report)
    captions = [c for c, _ in pages]
    assert sum(c.startswith(f"{second.label}: ") for c in captions) == 4
    assert sum(c.startswith("q1: ") for c in captions) == 4
    summary_text = " ".join(t.get_text() for _, fig in pages if _.startswith("Summary") for t in fig.texts)
    assert f"Results: {second.label}" in summary_text
    write_pngs([(c, f) for c, f in pages if c.startswith("Summary") or c.startswith(second.label)],
               artifacts_dir, "report-second-sensor", dpi=80)
    (html,) = write_report(report, [tmp_path / "q1.html"], pages=pages)
    text = html.read_text(encoding="utf-8")
    assert "Shot q1, second sensor (response_2)" in text
    assert "AYZ-3, serial SN0002, second sensor, digitizer role response_2" in text  # the sensor recorded


@pytest.mark.parametrize(("argv", "message"), [
    (["--accelerometer-2-model", "AYZ-3", "--accelerometer-2-serial", "SN0002"],
     "response_2: an accelerometer is named for it, but the rig records no response_2 channel"),
    (["--accelerometer-2-model", "AYZ-3"],
     "response_2: the accelerometer on it needs both its model and its serial number"),
])
def test_a_second_accelerometer_the_rig_cannot_record_is_refused_before_anything_moves(
        tmp_path: Path, argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    state = tmp_path / "state.json"
    rc = main(["shot", "--sim", "--out", str(tmp_path), "--yes", "--sim-state-file", str(state), *argv])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and message in err, err
    assert not state.exists() and not list(tmp_path.glob("*.h5"))  # the simulator never started


@pytest.mark.parametrize(("toml", "message"), [
    ("[world.signals]\nquadrature_error_deg = 60.0\n", "world.signals.quadrature_error_deg: must be at most 45"),
    ("[world.signals]\nquadrature_gain_ratio = 0.0\n", "world.signals.quadrature_gain_ratio: must be greater than 0"),
    ("[world.accelerometer_2]\nenabled = true\nmodes = []\n", "world.accelerometer_2.modes: at least one mode"),
    ("[world.accelerometer_2]\nconditioner_gain = -1.0\n", "world.accelerometer_2.conditioner_gain"),
])
def test_bad_sim_options_are_named(tmp_path: Path, toml: str, message: str) -> None:
    path = tmp_path / "sim.toml"
    path.write_text(toml, encoding="utf-8")
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_sim_config(path)


def _quadrature_table(path: Path, quadrature: np.ndarray | None = None) -> tuple[Path, float, float]:
    """A raw CSV, columns time_s,doppler,doppler_quadrature,response (that order), of a
    50 000 g half-sine on a flat sensor; (path, true peak m/s², true velocity change m/s)."""
    dt, start = 1e-8, 200e-6
    t = np.arange(60_000) * dt
    acc = half_sine_m_s2(t, 38.6e-6, 50_000 * G_M_S2, start)
    vel = velocity_m_s(acc, dt)
    u1, u2 = pm_beat(vel, dt, quadrature=QuadratureOutput(), rng=np.random.default_rng(11), quadrature_rng=np.random.default_rng(12))
    response = AccelerometerTruth(modes=(Mode(20e6, 0.7),)).respond(acc, dt)
    table = np.column_stack([t - start, u1, u2 if quadrature is None else quadrature, response])
    np.savetxt(path, table, delimiter=",", header="time_s,doppler,doppler_quadrature,response", comments="",
               fmt="%.10g")
    return path, 50_000 * G_M_S2, float(vel.max())


def test_reduce_command_takes_a_quadrature_column(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    raw, peak, velocity = _quadrature_table(tmp_path / "raw.csv")
    assert main(["reduce", str(raw), "-o", str(tmp_path / "record.csv"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["interferometer"] == "quadrature" and result["quadrature"]["phase_error_deg"] == pytest.approx(4, abs=0.3)
    assert result["peak_acceleration_m_s2"] == pytest.approx(peak, rel=PEAK_TOL)
    assert result["peak_velocity_m_s"] == pytest.approx(velocity, rel=1e-3)
    assert result["onset_time_s"] == pytest.approx(0.0, abs=3e-6)  # times count from the table's zero
    assert main(["reduce", str(raw), "-o", str(tmp_path / "again.csv")]) == 0
    assert re.search(r"^  interferometer +quadrature pair, Heydemann ellipse", capsys.readouterr().out, flags=re.M)


def test_reduce_command_names_a_bad_quadrature_column(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    raw, _, _ = _quadrature_table(tmp_path / "flat.csv", quadrature=np.full(60_000, 0.25))
    assert main(["reduce", str(raw), "-o", str(tmp_path / "record.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(raw) in err and "quadrature interferometer" in err and "constant" in err
    assert not (tmp_path / "record.csv").exists()


def test_hopkinson_sim_prints_the_extra_channels_a_rig_config_needs() -> None:
    from hopkinson.drivers.sim.world import WorldParams
    from hopkinson.rig.instruments import sim_digitizer_lines

    world = load_sim_config(REPO / "config" / "sim.toml").world
    # the shipped simulator's interferometer is a quadrature one (a bonded object's velocity comes
    # back through zero), and config/rig-sim.toml maps its second photodetector
    assert world.channels() == {"doppler": 1, "response": 2, "doppler_quadrature": 3}
    shipped = load_rig_config(REPO / "config" / "rig-sim.toml").digitizer.channels
    assert shipped["doppler_quadrature"] == "CH3" and "response_2" not in shipped
    on = WorldParams(signals=dataclasses.replace(world.signals, quadrature=True),
                     accelerometer_2=dataclasses.replace(world.accelerometer_2, enabled=True))
    lines = sim_digitizer_lines("keysight", on.channels())
    assert 'doppler_quadrature = "CHAN3", response_2 = "CHAN4"' in lines[0]
    assert lines[1].split() == ["[digitizer.ranges_v]", "doppler_quadrature", "=", "1.0,", "response_2", "=", "10.0"]


def test_a_simulated_world_with_one_photodetector_drops_the_shipped_quadrature_channel() -> None:
    """config/rig-sim.toml maps the quadrature photodetector; a simulated world without one
    leaves that channel flat, and the analysis would fail on it ("a quadrature channel is
    constant"): the simulated rig's digitizer config keeps only the signals its world makes."""
    from hopkinson.rig.instruments import sim_digitizer_config

    base = load_rig_config(REPO / "config" / "rig-sim.toml").digitizer
    one = sim_digitizer_config(base, "TCPIP::127.0.0.1::5025::SOCKET", "generic", {"doppler": 1, "response": 2})
    assert set(one.channels) == {"doppler", "response"} and set(one.ranges_v) == {"doppler", "response"}
    two = sim_digitizer_config(base, "TCPIP::127.0.0.1::5025::SOCKET", "keysight",
                               {"doppler": 1, "response": 2, "doppler_quadrature": 3})
    assert two.channels["doppler_quadrature"] == "CHAN3" and two.ranges_v["doppler_quadrature"] == 1.0


def test_the_report_opens_each_shot_with_its_verdict(fired) -> None:
    """The shot's results table starts with its ACCEPT/REPEAT line (rig.shot_verdict), the one the
    panel and `hopkinson shot` print: the resonance it names is the simulated sensor's (27 kHz)."""
    first = shot_report(fired.shot.path).shots[0]
    assert first.verdict is not None
    label, line = results_rows(first)[0]
    assert label == "verdict" and line == first.verdict.line()
    excited = re.search(r"resonance excited \((\d+(?:\.\d+)?) kHz\)", line)
    assert line.startswith(("ACCEPT — ", "REPEAT — ")) and excited is not None, line
    assert abs(float(excited.group(1)) / 27.0 - 1.0) < 0.01
    assert "−0.0 %" not in line  # a deviation that rounds to zero has no sign
