"""A record is never lost silently (issue 18): a full disk, a read-only or vanished shot folder at
STORE, or a disk that takes the raw shot but not its analysis. On a really small file system (a
tmpfs mounted for the test; skipped only where this process may not mount one): one line naming
the file and what failed, exit 3, the rig safe (read back from the simulated controller), no
temporary left behind, and the raw shot kept (in its folder, or rescued into the user's data
folder when the folder cannot take it)."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from hopkinson.rig.cli.main import main
from hopkinson.rig.shot import RESCUE_FOLDER, ShotRequestError
from hopkinson.rig.shotfile import read_shot
from tests.rig.test_cli_shot import _args, _assert_safe, _state, configs  # noqa: F401 (fixture)

Mount = Callable[[int], Path]


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Mount]:
    """mount(size_bytes) -> a fresh tmpfs of that size (unmounted after the test)."""
    mounted: list[Path] = []

    def mount(size_bytes: int) -> Path:
        point = tmp_path / f"small{len(mounted)}"
        point.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_bytes}", "tmpfs", str(point)],
                              capture_output=True, text=True)
        if done.returncode != 0:
            pytest.skip(f"cannot mount a small file system here: {done.stderr.strip() or done.returncode}")
        mounted.append(point)
        return point

    yield mount
    for point in mounted:
        subprocess.run(["umount", "-l", str(point)], capture_output=True)


def _rescued() -> list[Path]:
    folder = Path(os.environ["XDG_DATA_HOME"]) / "hopkinson" / RESCUE_FOLDER
    return sorted(folder.glob("*.h5")) if folder.is_dir() else []


def _no_temporaries(folder: Path) -> None:
    assert not [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]


def test_a_full_disk_at_store_is_one_line_exit_3_and_the_raw_shot_is_rescued(configs, capsys, small_fs) -> None:  # noqa: F811
    small = small_fs(400 * 1024)  # the 400 kB: a shot file of ~2.7 MB does not fit
    configs["out"] = small
    rc = main(_args(configs, "--yes"))
    _, err = capsys.readouterr()
    assert rc == 3 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "STORE failed: " in err and str(small) in err and "No space left on device" in err
    _assert_safe(_state(configs))  # the simulated controller's own valves
    _no_temporaries(small)
    (rescued,) = _rescued()
    assert f"saved instead in {rescued}" in err
    shot = read_shot(rescued)  # the whole raw shot, readable
    assert shot.raw is not None and shot.raw.channels["response"].codes.size > 1000


def test_a_read_only_folder_and_a_vanished_one_lose_nothing(make_rig, small_fs) -> None:
    rig = make_rig()
    readonly = small_fs(8 * 1024 * 1024)
    subprocess.run(["mount", "-o", "remount,ro", str(readonly)], check=True)
    with pytest.raises(ShotRequestError, match="the shot's log cannot be written .*nothing was moved"):
        rig.run(out_dir=readonly)  # read-only from the start: refused before anything moves
    assert rig.world.shots_fired == 0

    rig = make_rig()
    vanishing = rig.out_dir / "vanishing"
    vanishing.mkdir()
    rig.on_state("SAFE", lambda: shutil.rmtree(vanishing))  # the folder goes away before STORE
    outcome = rig.run(out_dir=vanishing)
    assert outcome.exit_code == 3 and outcome.final_state == "ABORTED"
    assert str(vanishing) in outcome.error and f"saved instead in {outcome.shot_path}" in outcome.error
    assert read_shot(outcome.shot_path).raw is not None and len(_rescued()) == 1
    rig.assert_safe()


def test_a_disk_that_takes_the_raw_shot_but_not_its_analysis_ends_in_fault_exit_3(make_rig, small_fs) -> None:
    rig = make_rig()
    first = rig.run()  # the size of one shot file on this rig
    size = first.shot_path.stat().st_size
    small = small_fs(int(size * 1.5) // 4096 * 4096 + 4096)  # the raw shot fits, a second copy does not
    outcome = rig.run(out_dir=small)
    assert outcome.exit_code == 3 and outcome.final_state == "FAULT" and outcome.safe_confirmed
    assert outcome.shot_path is not None and outcome.shot_path.parent == small
    assert f"the analysis could not be stored in {outcome.shot_path}" in outcome.error
    assert "No space left on device" in outcome.error and f"the raw shot is kept in {outcome.shot_path}" in outcome.error
    assert read_shot(outcome.shot_path).raw is not None  # the raw shot is intact
    with contextlib.suppress(FileNotFoundError):
        _no_temporaries(small)
    rig.assert_safe()



def test_a_report_on_a_full_disk_is_one_line(make_rig, small_fs, capsys) -> None:
    # a report on a full disk ended in a zlib traceback inside matplotlib's PDF writer
    rig = make_rig()
    shot = rig.run(pressure_bar=1.0).shot_path
    full = small_fs(64 * 1024)
    with contextlib.suppress(OSError), (full / "filler").open("wb") as fh:  # fill it up
        while True:
            fh.write(b"\0" * 4096)
            fh.flush()
    for name in ("r.pdf", "r.html"):
        assert main(["report", str(shot), "-o", str(full / name)]) == 2
        err = capsys.readouterr().err
        assert err == f"hopkinson: error: {full / name}: No space left on device\n"
    assert [p.name for p in full.iterdir()] == ["filler"]  # no temporary left behind
