"""`hopkinson analyse` (issue 18): a stored shot analysed again with today's method, as a new
analysis version beside the earlier ones, the raw data untouched; a shot whose analysis was
never stored analysed from its configuration snapshot; bad input one line, exit 2."""

from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from hopkinson.rig.cli.main import main
from hopkinson.rig.shotfile import analysis_results, read_shot

from tests.rig.test_cli_shot import _args, configs  # noqa: F401 (fixture)


@pytest.fixture
def shot_file(configs, capsys) -> Path:  # noqa: F811
    assert main(_args(configs, "--yes")) == 0
    capsys.readouterr()
    (path,) = configs["out"].glob("*.h5")
    return path


def test_a_stored_shot_gets_a_new_analysis_version_and_keeps_the_old_one(shot_file: Path, capsys) -> None:
    before = read_shot(shot_file)
    first = analysis_results(shot_file, 1)
    assert main(["analyse", str(shot_file), "--max-order", "6", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)["shots"]
    assert row["ok"] and row["version"] == 2 and row["error"] is None
    after = read_shot(shot_file)
    assert [a["version"] for a in after.analyses] == [1, 2]
    assert analysis_results(shot_file, 1) == first  # the earlier analysis, kept as it was
    assert after.results["params"]["max_order"] == 6 and first["params"]["max_order"] != 6
    for role, channel in before.raw.channels.items():  # the raw data untouched
        np.testing.assert_array_equal(after.raw.channels[role].codes, channel.codes)
    # the same method on the same data: the same model (the simulated sensor: 27 kHz, ζ 0.05)
    f_n = row["key_figures"]["natural_frequency_hz"]["value"]
    assert f_n == pytest.approx(27e3, rel=1e-3)


def test_a_shot_never_analysed_is_analysed_from_its_configuration(shot_file: Path, capsys) -> None:
    with h5py.File(shot_file, "r+") as f:  # as a shot whose analysis a full disk did not let store
        del f["analysis"], f["derived"], f["entry/record"]
        f.attrs["state"] = "raw"
    assert read_shot(shot_file).analyses == ()
    assert main(["analyse", str(shot_file)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{shot_file}: analysis version 1: order 2, f_n ") and out.count("\n") == 1
    f_n_khz = float(re.search(r"f_n ([0-9.]+) ± ", out).group(1))
    assert f_n_khz == pytest.approx(27.0, rel=1e-3)  # the simulated sensor's 27 kHz
    shot = read_shot(shot_file)
    assert shot.state == "analysed" and shot.results["params"]["amp_gain"] > 0


@pytest.mark.parametrize("make, message", [
    (lambda tmp: tmp / "nope.h5", "no such shot file or run folder"),
    (lambda tmp: tmp, "not a campaign run folder"),
])
def test_bad_input_is_one_line_exit_2(tmp_path: Path, capsys, make, message) -> None:
    assert main(["analyse", str(make(tmp_path))]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err


def test_a_file_that_is_not_a_shot_is_a_failed_row_exit_3(tmp_path: Path, capsys) -> None:
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5")
    assert main(["analyse", str(junk)]) == 3
    out = capsys.readouterr().out
    assert out.startswith(f"{junk}: FAILED: ") and out.count("\n") == 1
