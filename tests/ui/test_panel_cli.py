"""`hopkinson panel` as a process: the demo shot with a screenshot (what the README shows), and
bad input as one line on stderr with exit code 2."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from hopkinson.rig.shotfile import read_shot
from tests.rig.conftest import rig_config_with_few_draws

REPO = Path(__file__).resolve().parents[2]


def hopkinson(*args: str, timeout: float = 180.0) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    return subprocess.run([sys.executable, "-m", "hopkinson", *args], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=timeout)


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_demo_shot_fires_analyses_and_saves_the_window(tmp_path, artifacts_dir):
    sim = tmp_path / "sim.toml"
    sim.write_text("[world]\ntime_scale = 50.0\n", encoding="utf-8")
    shots = tmp_path / "shots"
    picture = tmp_path / "panel.png"
    result = hopkinson("panel", "--sim", "--sim-config", str(sim), "--demo-shot", "--screenshot", str(picture),
                       "--out", str(shots), "--runs", str(tmp_path / "runs"),
                       "--config", str(rig_config_with_few_draws(tmp_path)))  # (what the window shows of U)
    assert result.returncode == 0, result.stderr
    assert f"screenshot: {picture}" in result.stdout
    width, height = png_size(picture)
    assert width >= 1280 and height >= 800
    files = list(shots.glob("*.h5"))
    assert len(files) == 1
    shot = read_shot(files[0], load_raw=False)
    assert shot.state == "analysed" and shot.meta.operator == "demo"
    shutil.copyfile(picture, artifacts_dir / "panel-demo-shot.png")


def test_bad_input_is_one_line_and_exit_2(tmp_path):
    result = hopkinson("panel", "--demo-shot")
    assert result.returncode == 2
    assert result.stderr.strip() == "hopkinson: error: --demo-shot needs --sim (it fires a shot without asking)"
    missing = tmp_path / "nope.toml"
    result = hopkinson("panel", "--config", str(missing))
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and str(missing) in result.stderr
    result = hopkinson("panel", "--sim", "--sim-fault", "no-such-fault")
    assert result.returncode == 2 and "no-such-fault" in result.stderr and "Traceback" not in result.stderr
