"""Every way out goes SAFE, in real processes: `hopkinson shot`, `campaign run` and `panel` get
SIGTERM, SIGHUP or SIGINT and end with exit code 3 and a safe rig, read back from the
simulated controller itself (the simulator runs in this test's process and outlives the
command). The full state x signal matrix runs in-process (test_signals.py); this is a
representative set per command and signal.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hopkinson.rig.journal import Journal
from hopkinson.rig.lock import current_holder
from hopkinson.rig.logbook import read_log
from hopkinson.rig.sim_session import sim_session
from tests.rig.conftest import (
    REPO,
    assert_safe,
    fast_sim_config,
    read_until,
    rig_toml,
    short_timeouts_config,
)

TIME_SCALE = 10.0  # charging 4 bar takes ~0.8 s: a signal can land while the fill is open


@pytest.fixture
def sim(tmp_path: Path):
    with sim_session(short_timeouts_config(), fast_sim_config(TIME_SCALE)) as session:
        yield session, rig_toml(session, tmp_path / "rig.toml", evacuate_s=10.0, charge_s=20.0)


def _start(*argv: str, stream: str = "stdout") -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "hopkinson", *argv], cwd=REPO, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})


def _assert_safe(session) -> None:
    world = session.world
    assert_safe(world, session.config, digitizer_state=session.rig.digitizer.state)
    assert world.watchdog_state() == "off"  # disarmed by the process on its way out, never tripped
    assert current_holder(session.config) is None  # the rig is free again


@pytest.mark.parametrize("sig, at", [(signal.SIGTERM, r" CHARGE +charging:"), (signal.SIGHUP, r" ANALYSE ")])
def test_shot_gets_a_signal_goes_safe_and_exits_3(sim, tmp_path: Path, sig: signal.Signals, at: str) -> None:
    session, toml = sim
    proc = _start("shot", "--config", str(toml), "--yes", "--pressure-bar", "4.0", "--out", str(tmp_path / "shots"))
    head = read_until(proc, proc.stdout, at)
    proc.send_signal(sig)
    rest, err = proc.communicate(timeout=60)
    assert proc.returncode == 3, (head + rest, err)
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"hopkinson: error: interrupted ({sig.name}): "), err
    _assert_safe(session)
    (log,) = (tmp_path / "shots").glob("*.log.jsonl")
    entries = read_log(log)
    safe = [e for e in entries if e["type"] == "Note" and e["message"].startswith("rig safe")]
    if sig == signal.SIGTERM:  # aborted while charging: never fired, nothing recorded
        assert "shot aborted in CHARGE: operator: aborted: interrupted (SIGTERM)" in last and err.count("\n") == 1
        assert session.world.shots_fired == 0 and not list((tmp_path / "shots").glob("*.h5"))
        error = next(e for e in entries if e["type"] == "RigError")
        print(f"\nSIGTERM in CHARGE -> SAFE confirmed by reading back in "
              f"{_seconds(error['utc'], safe[-1]['utc']):.3f} s (abort noticed -> confirmed)")
    else:  # fired and recorded before the signal: the record is kept and SAFE ran again
        assert last.endswith("SAFE ran again and was confirmed") and "shot aborted after FIRE" in last
        assert "the recorded data is kept in " in last and "`hopkinson analyse` it" in last  # exit 3 said why
        assert session.world.shots_fired == 1 and len(list((tmp_path / "shots").glob("*.h5"))) == 1
        # the shot's SAFE, then one more: both on the screen and both in the shot's log
        assert len(safe) == 2 and (head + rest).count(" rig safe: ") == 2


def _seconds(a: str, b: str) -> float:
    from datetime import datetime

    def parse(text: str) -> datetime:
        return datetime.fromisoformat(text.replace("Z", "+00:00"))

    return (parse(b) - parse(a)).total_seconds()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_campaign_gets_a_signal_aborts_the_shot_goes_safe_and_exits_3(sim, tmp_path: Path, sig) -> None:
    session, toml = sim
    plan = tmp_path / "plan.toml"
    plan.write_text('name = "sig"\noperator = "t"\nauthorise_firing = true\n[accelerometer]\nmodel = "M"\n'
                    'serial = "S"\n[[shots]]\npressure_bar = 4.0\nprojectile = 3\nrepeats = 2\n', encoding="utf-8")
    run = tmp_path / "run"
    proc = _start("campaign", "run", str(plan), "--config", str(toml), "--out", str(run), "--no-report")
    read_until(proc, proc.stderr, r"\[1/2\] s001-r1 CHARGE \d")
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 3, err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"hopkinson: error: interrupted ({sig.name}): the current shot was aborted and the rig "
                           "made safe"), last
    _assert_safe(session)
    assert session.world.shots_fired == 0
    with Journal.open(run) as journal:
        assert journal.status("s001-r1").state.value == "ABORTED"
        assert journal.status("s001-r2").state.value == "PLANNED"  # the campaign stopped
    assert any(e["type"] == "RigError" and sig.name in e["message"]
               for e in read_log(run / "campaign.log.jsonl"))


def test_panel_gets_sigterm_makes_the_rig_safe_and_exits_3(sim, tmp_path: Path) -> None:
    session, toml = sim
    world = session.world
    # A rig left charged (as by a dead PC without a watchdog): the panel's SAFE must vent it.
    world.set_vent_valve(False)
    world.set_pressure_setpoint_bar(2.0)
    world.set_fill_valve(True)
    proc = _start("panel", "--config", str(toml), "--out", str(tmp_path / "shots"))
    deadline = time.monotonic() + 60
    while world.watchdog_state() != "armed":  # the panel holds the rig and feeds the watchdog
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    holder = current_holder(session.config)
    assert holder is not None and holder.pid == proc.pid and "panel" in holder.command
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    exit_s = time.monotonic() - sent
    assert proc.returncode == 3, err
    assert err.strip().splitlines()[-1] == ("hopkinson: error: interrupted (SIGTERM): rig safe: fire and fill valves "
                                            "closed, vent open, pump off"), err
    _assert_safe(session)
    print(f"\npanel: SIGTERM -> SAFE confirmed and exit 3 in {exit_s:.2f} s")
