"""`hopkinson plan-shot`: the pressure for a target peak per projectile from the bar model, which
projectile to load, the δ ≤ 1.06/f_n judgement, and a target beyond the rig's limits refused
with the reason (exit 2). Checked by firing the chosen pressure through the bar model again and
against the paper's rule in closed form."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from hopkinson.analysis.bar import predict_shot
from hopkinson.rig.cli.main import main
from hopkinson.rig.config import load_rig_config
from hopkinson.rig.config_paths import DEFAULT_SIM_RIG_CONFIG

G = 9.80665


def plan(capsys: pytest.CaptureFixture[str], *args: str, config: Path = DEFAULT_SIM_RIG_CONFIG
         ) -> tuple[int, str, str]:
    code = main(["plan-shot", *args, "--config", str(config)])
    out, err = capsys.readouterr()
    return code, out, err


def test_the_chosen_pressure_gives_the_target_and_the_paper_rule_is_judged(capsys) -> None:
    code, out, err = plan(capsys, "--peak-g", "50000", "--sensor-fn-hz", "27000", "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result["chosen_projectile"] == 3 and "δ = 38.6 µs ≤ 1.06/f_n" in result["reason"]
    rig = load_rig_config(DEFAULT_SIM_RIG_CONFIG).bar.rig()
    for option in result["projectiles"]:
        fired = predict_shot(rig, option["projectile"], pressure_bar=option["pressure_bar"])
        assert fired.peak_m_s2 == pytest.approx(50_000 * G, rel=0.01)  # the pressure gives the target
        assert option["paper_rule_holds"] == (option["width_s"] <= 1.06 / 27_000)
        assert option["reachable"] == (option["pressure_bar"] <= 8.0)  # rig-sim.toml's [limits] maximum
    text_code, text, _ = plan(capsys, "--peak-g", "50000", "--sensor-fn-hz", "27000")
    assert text_code == 0 and text.splitlines()[-1].startswith("load projectile No. 3: ")


def test_a_sensor_too_fast_for_every_pulse_is_said(capsys) -> None:
    code, out, _ = plan(capsys, "--peak-g", "20000", "--sensor-fn-hz", "60000", "--json")
    result = json.loads(out)
    assert code == 0 and all(o["paper_rule_holds"] is False for o in result["projectiles"])
    assert "the resonance will not be excited" in result["reason"]


def test_a_target_beyond_the_rig_is_refused_with_the_reason(capsys, tmp_path: Path) -> None:
    code, out, err = plan(capsys, "--peak-g", "200000")
    assert code == 2 and err.count("\n") == 1
    assert "200,000 g: no projectile reaches the target within the rig's pressure limits" in err
    # what No. 3 needs and reaches, fired through the bar model again: between the √p of a linear
    # bar (speed ∝ √p) and p of a peak ∝ v² from the launcher's calibration point (50 000 g at 2 bar)
    found = re.search(r"No\. 3 needs ([\d.]+) bar, above the rig's maximum 8 bar \(at most ([\d,]+) g\)", err)
    assert found, err
    needed_bar, top_g = float(found[1]), float(found[2].replace(",", ""))
    rig = load_rig_config(DEFAULT_SIM_RIG_CONFIG).bar.rig()
    assert predict_shot(rig, 3, pressure_bar=needed_bar).peak_m_s2 == pytest.approx(200_000 * G, rel=0.01)
    assert predict_shot(rig, 3, pressure_bar=8.0).peak_m_s2 == pytest.approx(top_g * G, rel=1e-5)
    assert 100_000 * 0.95 < top_g < 200_000
    # a rig whose own [bar] has a longer barrel reaches it
    text = DEFAULT_SIM_RIG_CONFIG.read_text()
    config = tmp_path / "rig.toml"
    config.write_text(text + "\n[bar]\nbarrel_length_m = 6.0\nlauncher_efficiency = 1.0\n")
    code, out, err = plan(capsys, "--peak-g", "200000", "--json", config=config)
    assert code == 0, err
    assert json.loads(out)["chosen_projectile"] == 3


@pytest.mark.parametrize(("args", "message"), [
    (["--peak-g", "-5"], "the target peak must be positive"),
    (["--peak-g", "5000", "--sensor-fn-hz", "0"], "--sensor-fn-hz must be positive"),
])
def test_bad_input_is_one_line_exit_2(capsys, args: list[str], message: str) -> None:
    code, _out, err = plan(capsys, *args)
    assert code == 2 and message in err and err.count("\n") == 1


def test_a_wrong_bar_key_names_the_file_and_key(capsys, tmp_path: Path) -> None:
    config = tmp_path / "rig.toml"
    config.write_text(DEFAULT_SIM_RIG_CONFIG.read_text() + "\n[bar]\nmaterial = \"unobtainium\"\n")
    code, _out, err = plan(capsys, "--peak-g", "5000", config=config)
    assert code == 2 and f"{config}: bar.material: must be one of" in err


def test_a_bonded_mount_plans_its_bipolar_pulse_and_a_wrong_mount_is_named(capsys, tmp_path: Path) -> None:
    """`[bar] mount = "bonded"` plans with the pulse that stays on the bar: the chosen pressure,
    fired through the bonded model again, gives the target; its bands are read above the
    spectrum's maximum (a bipolar pulse has nothing at DC). A mount the model does not know is
    one line naming the file and key."""
    config = tmp_path / "rig.toml"
    config.write_text(DEFAULT_SIM_RIG_CONFIG.read_text() + "\n[bar]\nmount = \"bonded\"\n")
    code, out, err = plan(capsys, "--peak-g", "50000", "--json", config=config)
    assert code == 0, err
    result = json.loads(out)
    rig = load_rig_config(config).bar.rig()
    assert rig.mount == "bonded"
    for option in result["projectiles"]:
        shot = predict_shot(rig, option["projectile"], pressure_bar=option["pressure_bar"])
        assert shot.peak_m_s2 == pytest.approx(50000 * G, rel=1e-6)
        assert abs(shot.delta_v_m_s) < 1e-3 * shot.peak_velocity_m_s  # it stays on the bar
        assert 0 < option["minus_3db_hz"] < option["supported_band_hz"]
    config.write_text(DEFAULT_SIM_RIG_CONFIG.read_text() + "\n[bar]\nmount = \"glued\"\n")
    code, _out, err = plan(capsys, "--peak-g", "5000", config=config)
    assert code == 2 and f"{config}: bar.mount: must be one of" in err and err.count("\n") == 1


def test_a_projectile_the_loader_cannot_take_is_refused_in_one_line(capsys, tmp_path: Path) -> None:
    """[bar.projectiles] numbers are the loader's positions, 1-3, as plans and shots take them: a
    No. 4 could be planned for and never fired."""
    config = tmp_path / "rig.toml"
    config.write_text(DEFAULT_SIM_RIG_CONFIG.read_text() + (
        "\n[[bar.projectiles]]\nnumber = 4\ncontact_stiffness_n_m = 1e7\n"
        "segments = [{material = \"C45\", length_m = 0.05, diameter_m = 0.016}]\n"))
    code, _out, err = plan(capsys, "--peak-g", "5000", config=config)
    assert code == 2 and f"{config}: bar.projectiles" in err and "number" in err and err.count("\n") == 1, err


def test_the_readmes_bar_table_is_a_valid_rig_configuration(capsys, tmp_path: Path) -> None:
    """The README's `[bar]` example, appended to the simulated rig's file, loads and plans: its one
    projectile (the paper's No. 3 written out) gives No. 3's pressure for 50 000 g."""
    readme = (Path(__file__).resolve().parents[2] / "docs" / "bar-physics.md").read_text(encoding="utf-8")
    block = re.search(r"```toml\n(\[bar\]\n.*?)```", readme, re.S)
    assert block, "docs/bar-physics.md has no ```toml [bar] example"
    config = tmp_path / "rig.toml"
    config.write_text(DEFAULT_SIM_RIG_CONFIG.read_text() + "\n" + block[1])
    code, out, err = plan(capsys, "--peak-g", "50000", "--json", config=config)
    assert code == 0, err
    result = json.loads(out)
    assert [o["projectile"] for o in result["projectiles"]] == [3] and result["chosen_projectile"] == 3
    own = result["projectiles"][0]
    paper = predict_shot(load_rig_config(DEFAULT_SIM_RIG_CONFIG).bar.rig(), 3, pressure_bar=own["pressure_bar"])
    assert own["width_s"] == pytest.approx(paper.equivalent_width_s, rel=1e-6)
