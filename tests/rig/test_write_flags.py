"""No write flag can overwrite an input or a record (issue 18): every file a command writes
(-o, --log-file, --sim-state-file, --sim-fire-log, --plot, --screenshot) is checked against
every file it reads, the others it writes and shot files, through symlinks and hard links,
before anything moves: one line, exit 2, the file untouched."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from hopkinson.fileio import HDF5_SIGNATURE
from hopkinson.rig.cli.main import main

CONFIG = Path(__file__).resolve().parents[2] / "config"


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    shutil.copy(CONFIG / "rig-sim.toml", tmp_path / "c.toml")
    shutil.copy(CONFIG / "campaigns" / "example.toml", tmp_path / "plan.toml")
    (tmp_path / "shot.h5").write_bytes(HDF5_SIGNATURE + b"\0" * 64)  # an existing shot file
    os.symlink(tmp_path / "c.toml", tmp_path / "link.toml")
    os.link(tmp_path / "c.toml", tmp_path / "hard.toml")
    return {name: tmp_path / name for name in ("c.toml", "plan.toml", "shot.h5", "link.toml", "hard.toml")}


@pytest.mark.parametrize("argv, flag, why", [
    (["shot", "--sim", "--yes", "--config", "{c.toml}", "--log-file", "{c.toml}"], "--log-file", "that is the input"),
    (["shot", "--sim", "--yes", "--config", "{c.toml}", "--sim-state-file", "{c.toml}"], "--sim-state-file",
     "that is the input"),
    (["shot", "--sim", "--yes", "--config", "{link.toml}", "--log-file", "{hard.toml}"], "--log-file",
     "that is the input"),  # a symlink read, a hard link written: the same file
    (["shot", "--sim", "--yes", "--config", "{c.toml}", "--log-file", "{shot.h5}"], "--log-file",
     "an HDF5 shot file exists"),
    (["campaign", "run", "{plan.toml}", "--sim", "--log-file", "{plan.toml}"], "--log-file", "that is the input"),
    (["campaign", "run", "{plan.toml}", "--sim", "--sim-fire-log", "{c.toml}", "--config", "{c.toml}"],
     "--sim-fire-log", "that is the input"),
    (["shot", "--sim", "--yes", "--config", "{c.toml}", "--log-file", "{hard.toml}.log",
      "--sim-state-file", "{hard.toml}.log"], "--sim-state-file", "that is also --log-file's file"),
])
def test_a_write_flag_naming_an_input_or_a_record_is_refused(files, capsys, argv, flag, why) -> None:
    before = {name: path.read_bytes() for name, path in files.items()}
    args = list(argv)
    for name, path in files.items():
        args = [a.replace("{" + name + "}", str(path)) for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"hopkinson: error: {flag} ") and why in err, err
    assert {name: path.read_bytes() for name, path in files.items()} == before  # nothing written over
    assert not list(files["c.toml"].parent.glob("*.log.jsonl"))  # nothing started
