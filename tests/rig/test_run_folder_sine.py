"""A campaign's run folder keeps a copy of the plan's sine calibration, and its plan copy names
that copy: `hopkinson report RUN_FOLDER` compares the shots with it even after the original is
gone. A plan naming a sine calibration that cannot be read is refused before anything exists."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from hopkinson.rig.cli.main import main
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.run_folder import create_run_folder, plan_naming_sine_calibration

PLAN = """# the technician's comments stay in the copy
name = "sine-run"
operator = "tester"
authorise_firing = true
[accelerometer]
model = "SIM-ACC"
serial = "S1"
sine_calibration = '../cal/sine.csv'   # beside the plans, not in the run folder
[defaults]
projectile = 3
[defaults.analysis]
max_order = 6
uncertainty = false
[[shots]]
pressure_bar = 1.5
"""
MODE_HZ, ZETA = 27_000.0, 0.05  # the simulated sensor (config/sim.toml world.accelerometer.modes)


def _sine_csv(path: Path) -> Path:
    """A sine calibration of a one-mode sensor, from its closed form (magnitude relative to DC)."""
    f = np.geomspace(500.0, 10e3, 8)
    r = f / MODE_HZ
    h = 1.0 / (1.0 - r**2 + 2j * ZETA * r)
    rows = "".join(f"{fi:.10g},{abs(hi):.10g},{np.degrees(np.angle(hi)):.10g},0.005\n"
                   for fi, hi in zip(f, h, strict=True))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("frequency_hz,magnitude,phase_deg,u_magnitude_rel\n" + rows, encoding="utf-8")
    return path


def test_the_run_folder_keeps_the_sine_calibration_and_the_report_compares_it(tmp_path: Path, capsys) -> None:
    sine = _sine_csv(tmp_path / "cal" / "sine.csv")
    original = sine.read_bytes()
    plan = tmp_path / "plans" / "plan.toml"
    plan.parent.mkdir()
    plan.write_text(PLAN, encoding="utf-8")
    sim = tmp_path / "sim.toml"
    sim.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
    run = tmp_path / "run"
    assert main(["campaign", "run", str(plan), "--sim", "--sim-config", str(sim), "--out", str(run),
                 "--no-report", "--json"]) == 0
    capsys.readouterr()
    assert (run / "sine.csv").read_bytes() == original
    copy = (run / "plan.toml").read_text(encoding="utf-8")
    assert copy == PLAN.replace("'../cal/sine.csv'", '"sine.csv"')  # only that value changed
    sine.unlink()  # the report reads the run folder's copy, not the original

    out = tmp_path / "report.html"
    assert main(["report", str(run), "-o", str(out), "--json"]) == 0
    comparison = json.loads(capsys.readouterr().out)["campaign"]["sine_comparison"]
    assert list(comparison) == ["s001-r1"]
    errors = comparison["s001-r1"]["magnitude_error_pct"]
    assert len(errors) == 8 and max(abs(e) for e in errors) < 2.0  # the model against the sensor's closed form
    page = out.read_text(encoding="utf-8")
    assert "sine.csv (8 points)" in page and "not compared" not in page


def test_a_sine_calibration_that_cannot_be_read_is_refused_before_the_run_exists(tmp_path: Path) -> None:
    plan = tmp_path / "plans" / "plan.toml"
    plan.parent.mkdir()
    plan.write_text(PLAN, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"plan.toml: accelerometer.sine_calibration: .*sine.csv: no such file"):
        create_run_folder(plan, tmp_path / "runs", "run-1")
    assert not (tmp_path / "runs" / "run-1").exists()
    _sine_csv(tmp_path / "cal" / "sine.csv").write_text("frequency_hz,magnitude,phase_deg\n1000,-1,0\n")
    with pytest.raises(ConfigError, match="magnitudes must be positive"):
        create_run_folder(plan, tmp_path / "runs", "run-1")
    assert not (tmp_path / "runs" / "run-1").exists()


@pytest.mark.parametrize("written", [
    'sine_calibration = "a\\\\b.csv"\n',  # a basic string with an escape
    'accelerometer.sine_calibration = "x.csv"\n',  # a dotted key at the top
    'accelerometer = { model = "M", serial = "S", sine_calibration = "x.csv" }\n',  # an inline table
])
def test_the_plan_copy_names_the_copy_whatever_way_the_key_is_written(written: str) -> None:
    head = 'name = "p"\noperator = "o"\n'
    text = head + (written if written.startswith("accelerometer") else
                   '[accelerometer]\nmodel = "M"\nserial = "S"\n' + written) + '[[shots]]\npressure_bar = 1.0\n'
    changed = plan_naming_sine_calibration(text, 'new "one".csv')
    doc, before = tomllib.loads(changed), tomllib.loads(text)
    assert doc["accelerometer"].pop("sine_calibration") == 'new "one".csv'
    before["accelerometer"].pop("sine_calibration")
    assert doc == before
    if not written.startswith("accelerometer = {"):  # only the value changed: the text is kept
        assert changed.replace('"new \\"one\\".csv"', "X") == text.replace(written.split("=", 1)[1].strip(), "X")
