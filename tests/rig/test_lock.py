"""One controller per rig (rig/lock.py): a second shot, campaign, panel or `hopkinson safe` on a
held rig is refused at once with exit 2, naming the holder, and touches nothing; a lock left by
a dead process is reclaimed; `current_holder` tells `status` who holds the rig; the lock folder
and file are checked (shared folder with the sticky bit, never through a symlink)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from hopkinson.rig.cli.main import main
from hopkinson.rig.lock import (
    RigLock,
    RigLockError,
    current_holder,
    lock_dir,
    lock_path,
    rig_address,
)
from hopkinson.rig.sim_session import sim_session
from tests.rig.conftest import fast_sim_config, rig_toml, short_timeouts_config

PLAN = """
name = "locked"
operator = "tester"
authorise_firing = true
[accelerometer]
model = "SIM-ACC"
serial = "L1"
[[shots]]
pressure_bar = 1.0
projectile = 3
"""


@pytest.fixture
def sim(tmp_path: Path):
    with sim_session(short_timeouts_config(), fast_sim_config()) as session:
        yield session, rig_toml(session, tmp_path / "rig.toml")


def test_a_held_rig_refuses_shot_campaign_panel_and_safe_and_nothing_is_touched(sim, tmp_path, capsys) -> None:
    session, toml = sim
    before = session.state()
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN, encoding="utf-8")
    with RigLock.acquire(session.config, "hopkinson shot --pressure-bar 4 (the first one)") as held:
        assert current_holder(session.config) == held.holder
        commands = {
            "shot": ["shot", "--config", str(toml), "--yes", "--out", str(tmp_path / "shots")],
            "campaign": ["campaign", "run", str(plan), "--config", str(toml), "--out", str(tmp_path / "run"),
                         "--no-report"],
            "safe": ["safe", "--config", str(toml)],
            "panel": ["panel", "--config", str(toml), "--screenshot", str(tmp_path / "panel.png")],
        }
        for name, argv in commands.items():
            assert main(argv) == 2, name
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and err[0].startswith("hopkinson: error: the rig "), (name, err)
            assert f"is held by pid {os.getpid()}" in err[0] and "(the first one)" in err[0], (name, err)
            if name == "safe":  # it does not fight the holder, but says how to ask it to stop
                assert "--stop-holder" in err[0]
    after = session.state()
    assert after == {**before, "sim_time_s": after["sim_time_s"]}  # no valve, set-point or pump moved
    assert session.world.shots_fired == 0 and not (tmp_path / "run").exists()
    assert not list((tmp_path / "shots").iterdir())  # no shot file, no log
    assert current_holder(session.config) is None  # released


def test_a_lock_left_by_a_killed_process_is_reclaimed(tmp_path: Path) -> None:
    config = short_timeouts_config()
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        from hopkinson.rig.config import load_rig_config
        from hopkinson.rig.lock import RigLock
        RigLock.acquire(load_rig_config({str(Path(config.path))!r}), "hopkinson panel (killed)")
        print("held", flush=True)
        import time; time.sleep(60)
    """)], stdout=subprocess.PIPE, text=True, env=os.environ.copy())
    try:
        assert holder.stdout.readline().strip() == "held"
        found = current_holder(config)
        assert found is not None and found.pid == holder.pid and found.command == "hopkinson panel (killed)"
        with pytest.raises(RigLockError, match=f"held by pid {holder.pid}"):
            RigLock.acquire(config, "second")
    finally:
        holder.kill()
        holder.wait()
    with RigLock.acquire(config, "third") as lock:
        assert lock.reclaimed is not None and lock.reclaimed.pid == holder.pid
        assert lock.reclaimed.command == "hopkinson panel (killed)"


def test_lock_folder_and_file_checks(tmp_path: Path, monkeypatch) -> None:
    shared = tmp_path / "shared"
    monkeypatch.setenv("HOPKINSON_LOCK_DIR", str(shared))
    assert lock_dir() == shared and os.stat(shared).st_mode & 0o1777 == 0o1777  # created sticky, for every user
    config = short_timeouts_config()
    path = lock_path(rig_address(config))
    assert path.parent == shared and rig_address(config) == config.valve_controller.address
    with RigLock.acquire(config, "one"):
        assert os.stat(path).st_mode & 0o777 == 0o666  # the next user may take it
    # A planted symlink is never followed.
    target = tmp_path / "victim.txt"
    target.write_text("keep me", encoding="utf-8")
    path.unlink()
    path.symlink_to(target)
    with pytest.raises(RigLockError, match="symlink is never followed"):
        RigLock.acquire(config, "two")
    assert target.read_text(encoding="utf-8") == "keep me"
    # A folder anyone may write into without the sticky bit: another user could swap locks.
    open_folder = tmp_path / "open"
    open_folder.mkdir()
    os.chmod(open_folder, 0o777)
    monkeypatch.setenv("HOPKINSON_LOCK_DIR", str(open_folder))
    with pytest.raises(RigLockError, match="without the sticky bit"):
        RigLock.acquire(config, "three")
