"""`pip install .` (not editable) gives a working tool: one import name, the shipped
configurations as package data, `hopkinson --version`, and a simulated shot from any folder."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The project built as a wheel and installed (without dependencies: the venv has them)
    into a folder of its own; returns that folder."""
    work = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
                    "--wheel-dir", str(work / "dist"), str(REPO)], check=True, capture_output=True, timeout=300,
                   cwd=work)
    (wheel,) = (work / "dist").glob("hopkinson-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith((".dist-info", ".data"))}
    assert tops == {"hopkinson"}, tops
    assert "hopkinson/config/rig-sim.toml" in names and "hopkinson/config/campaigns/demo.toml" in names
    # the lab's record: its schema's migrations ship as package data (alembic runs them from there)
    assert "hopkinson/lab/migrations/env.py" in names and "hopkinson/lab/migrations/script.py.mako" in names
    assert any(n.startswith("hopkinson/lab/migrations/versions/v0001") for n in names)
    site = work / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(site),
                    str(wheel)], check=True, capture_output=True, timeout=300)
    return site


def _run(site: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(site), HOPKINSON_CONFIG_DIR=str(cwd / "no-user-config"),
               XDG_DATA_HOME=str(cwd / "data"))
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=240)


def test_installed_wheel_runs_from_any_folder(installed: Path, tmp_path: Path) -> None:
    done = _run(installed, tmp_path, "-m", "hopkinson", "--version")
    assert done.returncode == 0 and done.stdout.startswith("hopkinson "), done.stderr
    where = _run(installed, tmp_path, "-c", "import hopkinson.rig.config_paths as c; print(c.DEFAULT_SIM_RIG_CONFIG)")
    assert Path(where.stdout.strip()).is_relative_to(installed), (where.stdout, where.stderr)
    shot = _run(installed, tmp_path, "-m", "hopkinson", "shot", "--sim", "--yes", "--pressure-bar", "2",
                "--out", "shots", "--json", "--draws", "50")  # (the fewest draws: the figures are not the point)
    assert shot.returncode == 0, shot.stderr
    assert list((tmp_path / "shots").glob("*.h5"))
    # the shot went into the lab's record (SQLite in the data folder), its schema from the installed migrations
    sensor = _run(installed, tmp_path, "-m", "hopkinson", "lab", "status", "--json",
                  "--config", where.stdout.strip())
    assert sensor.returncode == 0 and '"shots":1' in sensor.stdout, (sensor.stdout, sensor.stderr)


def test_a_lab_rig_toml_in_the_user_config_dir_is_the_default(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from hopkinson.rig import config_paths

    own = tmp_path / "rig.toml"
    monkeypatch.setenv("HOPKINSON_CONFIG_DIR", str(tmp_path))
    assert config_paths.default_rig_config() == config_paths.SHIPPED_RIG_CONFIG
    own.write_text("# the lab's own\n")
    assert config_paths.default_rig_config() == own
