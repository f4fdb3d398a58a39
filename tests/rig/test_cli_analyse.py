"""`hopkinson analyse` (issue 18): a stored shot analysed again with today's method, as a new
analysis version beside the earlier ones, the raw data untouched; a shot whose analysis was
never stored analysed from its configuration snapshot; bad input one line, exit 2. A lab's
archive (issue 43): a folder tree of run folders and loose shot files, analysed in parallel
worker processes, bad files one line each, the run journals following."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from hopkinson.rig.cli.main import main
from hopkinson.rig.journal import Journal
from hopkinson.rig.run_folder import RunFolder
from hopkinson.rig.shotfile import analysis_results, read_shot
from tests.rig.conftest import read_until
from tests.rig.test_cli_shot import _args, configs  # noqa: F401 (fixture)


@pytest.fixture(scope="module")
def fired(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Where the module keeps its one fired shot (`shot_file` fires it the first time)."""
    return {"folder": tmp_path_factory.mktemp("fired")}


@pytest.fixture
def shot_file(configs, capsys, fired: dict[str, Path]) -> Path:  # noqa: F811
    """A shot fired with `hopkinson shot --sim` (once per module: each test gets its own copy of
    the shot folder, the shot file and its log, as the shot left them)."""
    if "shot" not in fired:
        assert main(_args(configs, "--yes")) == 0
        capsys.readouterr()
        (path,) = configs["out"].glob("*.h5")
        shutil.copytree(configs["out"], fired["folder"] / "shots")
        fired["shot"] = fired["folder"] / "shots" / path.name
        return path
    shutil.copytree(fired["folder"] / "shots", configs["out"])
    return configs["out"] / fired["shot"].name


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
    # its verdict, as the panel shows it: the resonance it names is the simulated sensor's
    assert row["verdict"]["decision"] in ("ACCEPT", "REPEAT") and "resonance excited (27" in row["verdict"]["line"]


def _never_analysed(shot_file: Path, **settings: object) -> None:
    """The shot as one whose analysis a full disk did not let store (`settings`: changed in its
    recorded shot settings)."""
    with h5py.File(shot_file, "r+") as f:
        del f["analysis"], f["derived"], f["entry/record"]
        f.attrs["state"] = "raw"
    if settings:
        with h5py.File(shot_file, "r+") as f:
            config = json.loads(f.attrs["config_json"])
            config["shot_settings"].update(settings)
            f.attrs["config_json"] = json.dumps(config)
    assert read_shot(shot_file).analyses == ()


def test_a_shot_never_analysed_is_analysed_from_its_configuration(shot_file: Path, capsys) -> None:
    _never_analysed(shot_file, analysis_options={"uncertainty": True, "draws": 50})
    assert main(["analyse", str(shot_file)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{shot_file}: analysis version 1: order 2, f_n ") and out.count("\n") == 1
    assert re.search(r" \| (ACCEPT|REPEAT): \S.*\n$", out), out  # the verdict closes the shot's one line
    f_n_khz = float(re.search(r"f_n ([0-9.]+) ± ", out).group(1))
    assert f_n_khz == pytest.approx(27.0, rel=1e-3)  # the simulated sensor's 27 kHz
    shot = read_shot(shot_file)
    assert shot.state == "analysed" and shot.results["params"]["amp_gain"] > 0


def test_a_shot_never_analysed_keeps_what_its_request_asked(shot_file: Path, capsys) -> None:
    """The options the shot's request asked (recorded in its settings: a plan's order, the draws)
    and its sensor's own sensitivity, stated transverse sensitivity and asymmetry bound are the
    re-analysis' too, not the rig configuration's."""
    _never_analysed(shot_file, analysis_options={"max_order": 5, "uncertainty": False},
                    sensitivity_v_per_m_s2=3.0e-7, transverse_sensitivity_rel=0.02, asymmetry_bound_rel=0.05)
    assert main(["analyse", str(shot_file), "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)["shots"]
    assert row["ok"], row
    params = read_shot(shot_file).results["params"]
    assert params["max_order"] == 5 and params["uncertainty"] is False
    assert params["sensitivity_v_per_m_s2"] == 3.0e-7 and params["transverse_sensitivity_rel"] == 0.02
    assert params["asymmetry_bound_rel"] == 0.05


@pytest.mark.parametrize("make, message", [
    (lambda tmp: tmp / "nope.h5", "no such shot file or run folder"),
    (lambda tmp: tmp, "not a campaign run folder"),
])
def test_bad_input_is_one_line_exit_2(tmp_path: Path, capsys, make, message) -> None:
    assert main(["analyse", str(make(tmp_path))]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err


def test_a_file_that_is_not_a_shot_is_a_failed_row_exit_4(tmp_path: Path, capsys) -> None:
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5")
    assert main(["analyse", str(junk)]) == 4  # an analysis that failed, as for `shot` (docs/exit-codes.md)
    out = capsys.readouterr().out
    assert out.startswith(f"{junk}: FAILED: ") and out.count("\n") == 1


# ------------------------------------------------------------------ an archive: folder trees, in parallel
PLAN = """
name = "archive"
operator = "tester"
authorise_firing = true
[accelerometer]
model = "SIM-ACC"
serial = "A1"
[defaults]
projectile = 3
[defaults.analysis]
max_order = 6
uncertainty = false
[[shots]]
pressure_bar = 1.3
[[shots]]
pressure_bar = 2.4
"""


@pytest.fixture(scope="module")
def campaign_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A campaign of two shots fired on the simulated rig (100x real time), as `make demo` leaves one."""
    base = tmp_path_factory.mktemp("archive-run")
    plan = base / "plan.toml"
    plan.write_text(PLAN, encoding="utf-8")
    sim = base / "sim-fast.toml"
    sim.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
    assert main(["campaign", "run", str(plan), "--sim", "--sim-config", str(sim), "--out", str(base / "run"),
                 "--no-report"]) == 0
    return base / "run"


@pytest.fixture
def archive(campaign_run: Path, tmp_path: Path) -> dict[str, Path]:
    """A lab's archive: a campaign run folder, a loose shot two folders down, a file that is not a shot."""
    root = tmp_path / "archive"
    run = shutil.copytree(campaign_run, root / "2026" / "run")
    loose = root / "2025" / "bench" / "loose.h5"
    loose.parent.mkdir(parents=True)
    shutil.copy(sorted((run / "shots").glob("*.h5"))[0], loose)
    (root / "2025" / "junk.h5").write_bytes(b"not hdf5")
    (root / "2025" / "notes.txt").write_text("not a shot")
    return {"root": root, "run": run, "loose": loose, "junk": root / "2025" / "junk.h5"}


def journal_states(run: Path) -> dict[str, tuple[str, dict, str]]:
    with Journal.open(run) as journal:
        return {s.shot.id: (s.state.value, s.info, s.updated_utc) for s in journal.statuses()}


def test_a_folder_tree_is_analysed_in_parallel_bad_files_one_line_each(archive: dict[str, Path], capsys) -> None:
    run = archive["run"]
    shots = sorted((run / "shots").glob("*.h5"))
    before = journal_states(run)
    assert len(shots) == 2 and all(s[0] == "ANALYSED" for s in before.values())
    code = main(["analyse", str(archive["root"]), "--jobs", "2", "--max-order", "2", "--json"])
    rows = {Path(r["path"]): r for r in json.loads(capsys.readouterr().out)["shots"]}
    assert code == 4  # the junk file failed (an analysis that failed: docs/exit-codes.md); the rest did not stop
    assert set(rows) == {*shots, archive["loose"], archive["junk"]}
    assert not rows[archive["junk"]]["ok"] and "junk.h5" in rows[archive["junk"]]["error"]
    for path in (*shots, archive["loose"]):
        assert rows[path]["ok"] and rows[path]["version"] == 2 and rows[path]["cpu_s"] > 0, rows[path]
        assert [a["version"] for a in read_shot(path).analyses] == [1, 2]
        assert read_shot(path).results["params"]["max_order"] == 2
    after = journal_states(run)  # the run's journal follows its shots
    for shot_id, (state, info, updated) in after.items():
        assert state == "ANALYSED" and updated > before[shot_id][2]
        assert info["order"] == rows[run / "shots" / f"{shot_id}.h5"]["key_figures"]["order"]
    assert not list(archive["root"].rglob("*.tmp"))  # every file written whole


def test_the_demos_shots_folder_named_alone_keeps_its_journal(archive: dict[str, Path], capsys) -> None:
    """A run folder's shots/ folder (as `make demo` leaves it), named alone: its shots' journal
    follows each outcome, an analysis that fails as ANALYSIS_FAILED with its reason."""
    folder = archive["run"] / "shots"
    # an order the first shot's band cannot hold (48 bins: at most order 46) fails its analysis; the
    # method's band across the pulse's nulls holds more bins on the second (order 3, asked before,
    # now fits both shots stably: an over-order is a warning, not a failure)
    code = main(["analyse", str(folder), "--jobs", "2", "--order", "60", "--no-uncertainty", "--json"])
    rows = json.loads(capsys.readouterr().out)["shots"]
    assert code == (0 if all(r["ok"] for r in rows) else 4) and any(not r["ok"] for r in rows)  # 4: one failed
    states = journal_states(archive["run"])
    for row in rows:
        state, info, _ = states[Path(row["path"]).stem]
        assert (state, info.get("error")) == (("ANALYSED", None) if row["ok"] else ("ANALYSIS_FAILED", row["error"]))


def test_the_lines_come_in_the_order_found_and_parallel_equals_serial(archive: dict[str, Path], capsys) -> None:
    folder = archive["run"]
    assert main(["analyse", str(folder), "--jobs", "1", "--max-order", "2"]) == 0
    serial = capsys.readouterr().out.splitlines()
    assert main(["analyse", str(folder), "--jobs", "2", "--max-order", "2"]) == 0
    parallel = capsys.readouterr().out.splitlines()
    shots = sorted((folder / "shots").glob("*.h5"))
    assert [line.split(": analysis version ")[0] for line in serial] == [str(s) for s in shots]
    assert [line.replace("version 3", "version 2") for line in parallel] == serial  # the same figures


def test_a_run_folder_in_use_is_refused_before_anything_moves(archive: dict[str, Path], capsys) -> None:
    run = archive["run"]
    held = RunFolder(run).lock()  # as a campaign running there holds it
    try:
        assert main(["analyse", str(archive["root"]), "--jobs", "2"]) == 2
    finally:
        held.release()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "in use by another process" in err
    assert all(len(read_shot(p).analyses) == 1 for p in run.glob("shots/*.h5"))  # nothing analysed
    assert len(read_shot(archive["loose"]).analyses) == 1


@pytest.mark.parametrize("jobs", ["0", "two"])
def test_jobs_must_be_a_positive_count(jobs: str, capsys) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["analyse", "x.h5", "--jobs", jobs])
    assert stop.value.code == 2 and "--jobs" in capsys.readouterr().err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_archive_run_stops_starting_shots_and_loses_none(shot_file: Path, tmp_path: Path, sig) -> None:
    """Ctrl-C (to the whole process group, as a terminal sends it) or SIGTERM (to the command)
    after the first shot is told: no shot starts after it, the ones running finish and are told,
    every file is whole (one version or two, no temporary left), exit code 128 + the signal."""
    tree = tmp_path / "tree"
    for i in range(8):
        (tree / f"{i % 2}").mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shot_file, tree / f"{i % 2}" / f"s{i}.h5")
    proc = subprocess.Popen([sys.executable, "-m", "hopkinson", "analyse", str(tree), "--jobs", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        first = read_until(proc, proc.stdout, r"analysis version 2: .*\n")
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)  # a terminal's Ctrl-C reaches the workers too
        else:
            proc.send_signal(sig)
        rest, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    told = (first + rest.decode()).splitlines()
    assert proc.returncode == 128 + sig and "Traceback" not in err.decode()
    versions = {p: [a["version"] for a in read_shot(p, load_raw=False).analyses] for p in sorted(tree.rglob("*.h5"))}
    analysed = {str(p) for p, v in versions.items() if v == [1, 2]}
    assert all(v in ([1], [1, 2]) for v in versions.values()) and not list(tree.rglob("*.tmp"))
    assert {line.split(": analysis version 2")[0] for line in told} == analysed  # each analysed shot told
    assert 1 <= len(analysed) < len(versions)  # the rest never started
