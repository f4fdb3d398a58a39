"""`hopkinson shot --sim`: exit codes, the one-line messages, the simulator's final state file,
confirmation (--yes, a terminal prompt, none), and Ctrl-C deferred until SAFE has run."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from hopkinson.rig.cli.main import main
from hopkinson.rig.config import load_rig_config
from hopkinson.rig.shotfile import read_shot
from tests.rig.conftest import assert_state_safe, read_until

REPO = Path(__file__).resolve().parents[2]
LINE = re.compile(r"^(\d\d:\d\d:\d\d\.\d\d\d) (\S+)")  # every event line: its UTC time, then the state


def _states(out: str) -> list[str]:
    return [m.group(2) for m in map(LINE.match, out.splitlines()) if m]


@pytest.fixture
def configs(tmp_path: Path) -> dict[str, Path]:
    """A rig config with short timeouts and a simulator 100x (and 10x) faster than real time."""
    text = (REPO / "config" / "rig-sim.toml").read_text(encoding="utf-8")
    short = {"evacuate_s": 2.0, "charge_s": 3.0, "arm_s": 1.0, "capture_s": 2.0, "safe_s": 3.0}
    for key, value in short.items():
        text, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
        assert n == 1, key
    rig = tmp_path / "rig.toml"
    rig.write_text(text, encoding="utf-8")
    fast, slow = tmp_path / "sim-fast.toml", tmp_path / "sim-10x.toml"
    fast.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
    slow.write_text("[world]\ntime_scale = 10.0\n", encoding="utf-8")
    return {"rig": rig, "sim": fast, "sim10": slow, "out": tmp_path / "shots", "state": tmp_path / "state.json"}


def _args(c: dict[str, Path], *extra: str, sim: str = "sim", uncertainty: bool = False) -> list[str]:
    """The shot's arguments; the Monte Carlo uncertainty only where a test is about the figures."""
    return ["shot", "--sim", "--config", str(c["rig"]), "--sim-config", str(c[sim]), "--out", str(c["out"]),
            "--pressure-bar", "1.0", "--sim-state-file", str(c["state"]), *extra,
            *(() if uncertainty else ("--no-uncertainty",))]


def _state(c: dict[str, Path]) -> dict:
    return json.loads(c["state"].read_text(encoding="utf-8"))


def _assert_safe(state: dict, **kw: object) -> None:
    """tests/rig/conftest.py's assert_safe, on the simulator's state file."""
    assert_state_safe(state, load_rig_config(REPO / "config" / "rig-sim.toml"), **kw)  # type: ignore[arg-type]


def test_shot_with_yes_fires_stores_and_reports_json(configs, capsys) -> None:
    rc = main(_args(configs, "--yes", "--json", "--shot-name", "s1", "--operator", "ann",
                    "--accelerometer-model", "M1", "--accelerometer-serial", "SN9"))
    out, err = capsys.readouterr()
    assert rc == 0
    result = json.loads(out)
    assert result["final_state"] == "DONE" and result["exit_code"] == 0 and result["fired"] is True
    assert result["shot_path"] == str(configs["out"] / "s1.h5")
    shot = read_shot(result["shot_path"])
    assert (shot.meta.operator, shot.meta.accelerometer_model, shot.meta.accelerometer_serial) == ("ann", "M1", "SN9")
    assert shot.meta.simulated_truth["shot_number"] == 1
    state = _state(configs)
    _assert_safe(state)
    assert state["shots_fired"] == 1 and result["sim_state"]["shots_fired"] == 1
    assert result["analysis_error"] is None and err == ""
    assert shot.state == "analysed" and result["results"] == shot.results
    assert result["results"]["fbsd_hz"]["5"] > 0


def test_analysis_failure_exits_4_and_says_why(configs, capsys) -> None:
    """Issue 44: it exited 0, and `hopkinson shot && next-step` went on as if calibrated."""
    # A 20 kS/s analysis rate leaves 40 samples of the 2 ms record: too few to identify a model.
    rc = main(_args(configs, "--yes", "--json", "--sample-rate", "20000"))
    out, err = capsys.readouterr()
    result = json.loads(out)
    assert rc == 4 and result["exit_code"] == rc and result["final_state"] == "DONE" and result["analysis_error"]
    assert err.startswith(f"hopkinson: error: the shot is recorded in {result['shot_path']} but its analysis failed")
    assert "(exit 4: `hopkinson analyse` it again once the cause is fixed)" in err
    assert "too short" in result["analysis_error"] and err.count("\n") == 1
    assert read_shot(result["shot_path"]).state == "analysis_failed"


def test_shot_prints_the_states_and_the_key_figures(configs, capsys) -> None:
    assert main(_args(configs, "--yes", "--draws", "50", uncertainty=True)) == 0  # the line's shape, not the U
    out = capsys.readouterr().out
    states = _states(out)
    assert [s for i, s in enumerate(states) if i == 0 or states[i - 1] != s] == [
        "CHECK", "EVACUATE", "CHARGE", "ARM", "FIRE", "CAPTURE", "SAFE", "STORE", "ANALYSE", "DONE"]
    assert re.search(r"^results: .*f_n 2\d\.\d+ ± 0\.\d+ kHz, zeta 0\.0\d+ ± 0\.\d+, FBSD ±5 % \d\.\d+ ± 0\.\d+ kHz", out, flags=re.M)
    # the verdict the panel shows, on its own line; the resonance it names is the simulated sensor's (27 kHz)
    verdict = re.search(r"^verdict: +(ACCEPT|REPEAT) — fit .* resonance excited \((\d+(?:\.\d+)?) kHz\)", out, flags=re.M)
    assert verdict is not None, out
    assert abs(float(verdict.group(2)) / 27.0 - 1.0) < 0.01


def test_a_controller_unreachable_at_session_start_is_named_with_a_fix(configs, capsys) -> None:
    # issue 18: exit 2 as "bad input" with pymodbus's own text ("... unbounded read bytes ...")
    assert main(_args(configs, "--yes", "--sim-fault", "modbus-disconnect")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "unbounded" not in err
    assert "valve controller" in err and "could not be reached before the shot" in err
    assert "nothing was moved" in err and "Fix: " in err and "hopkinson probe" in err
    state = _state(configs)
    assert state["shots_fired"] == 0 and state["reservoir_pressure_bar"] <= 0.05


def test_without_yes_and_without_a_terminal_nothing_moves(configs, capsys) -> None:
    # issue 18: it used to evacuate and charge to the set pressure, then abort at ARM for want of
    # a confirmation nobody could give. Refused before the simulator even starts, exit 2.
    rc = main(_args(configs))  # pytest's standard input is not a terminal
    out, err = capsys.readouterr()
    assert rc == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("hopkinson: error: nothing can confirm this shot: standard input is not a terminal")
    assert "--yes" in err and "nothing was moved" in err and _states(out) == []
    assert not configs["state"].exists()  # the simulated rig was never started
    assert not configs["out"].exists()


@pytest.mark.parametrize("fault, where, reason", [
    ("door-open", "CHECK: valve controller", "interlock lost: door/guard open"),
    ("no-trigger", "CAPTURE: digitizer", "the shot was fired but nothing was recorded"),
])
def test_sim_fault_aborts_with_one_line_and_the_state_file_is_safe(configs, capsys, fault, where, reason) -> None:
    rc = main(_args(configs, "--yes", "--sim-fault", fault))
    _, err = capsys.readouterr()
    assert rc == 3 and err.count("\n") == 1
    assert err.startswith(f"hopkinson: error: shot aborted in {where}") and reason in err
    state = _state(configs)
    _assert_safe(state)
    assert state["faults"] == [fault]
    assert state["shots_fired"] == (1 if fault == "no-trigger" else 0)


@pytest.mark.parametrize("extra, message", [
    (("--pressure-bar", "50"), "pressure_bar: 50 bar is outside the rig's limits"),
    (("--sim-fault", "gremlins"), "unknown simulator fault 'gremlins'"),
    (("--max-order", "0"), "max_order"),
    (("--sample-rate", "0"), "sample_rate_hz: a finite number (above 0"),  # fell back to the default before
])
def test_bad_input_exits_2_with_one_line(configs, capsys, extra, message) -> None:
    rc = main(_args(configs, "--yes", *extra))
    out, err = capsys.readouterr()
    assert rc == 2 and err.count("\n") == 1 and message in err and "Traceback" not in err
    assert not configs["state"].exists()  # nothing was started


def test_sim_options_need_sim_and_config_must_exist(configs, capsys, tmp_path) -> None:
    assert main(["shot", "--config", str(configs["rig"]), "--sim-fault", "estop"]) == 2
    assert "need --sim" in capsys.readouterr().err
    assert main(["shot", "--sim", "--config", str(tmp_path / "nope.toml"), "--yes"]) == 2
    assert "nope.toml: no such file" in capsys.readouterr().err


# -- real processes: Ctrl-C and the terminal prompt ---------------------------------------------------
def test_ctrl_c_during_charge_goes_safe_then_exits_3(configs) -> None:
    args = _args(configs, "--yes", sim="sim10")
    args[args.index("1.0")] = "6.0"  # 6 bar take ~1.2 s to charge at 10x: time to press Ctrl-C
    proc = subprocess.Popen([sys.executable, "-m", "hopkinson", *args], cwd=REPO, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    head = read_until(proc, proc.stdout, "CHARGE")
    proc.send_signal(signal.SIGINT)
    rest, err = proc.communicate(timeout=60)
    out = head + rest
    assert proc.returncode == 3, (out, err)
    assert err.startswith("hopkinson: error: interrupted (SIGINT): shot aborted in CHARGE: operator: aborted: "
                          "interrupted (SIGINT)") and err.count("\n") == 1
    states = _states(out)
    assert states.index("SAFE") > states.index("CHARGE") and "FIRE" not in states
    assert "rig safe" in out
    state = _state(configs)
    _assert_safe(state)
    assert state["shots_fired"] == 0


def test_yes_typed_at_the_terminal_prompt_fires(configs) -> None:
    master, slave = os.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "hopkinson", *_args(configs)], cwd=REPO, text=True,
                            stdin=slave, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    os.close(slave)
    try:
        read_until(proc, proc.stdout, "waiting for the fire confirmation")
        os.write(master, b"yes\n")
        out, err = proc.communicate(timeout=60)
    finally:
        os.close(master)
    assert proc.returncode == 0, (out, err)
    assert "Type yes to FIRE" in err
    assert "fire confirmed" in out and "DONE" in out
    state = _state(configs)
    assert state["shots_fired"] == 1
    _assert_safe(state)


@pytest.mark.parametrize("safe_again, expected", [
    (None, "it came after the shot had ended with the rig confirmed safe; nothing was moved after that"),
    ((True, None), "the shot was recorded before it; SAFE ran again and was confirmed"),
    ((False, "vent valve stuck"), "SAFE NOT CONFIRMED: vent valve stuck; check the rig by hand"),
])
def test_a_late_signal_is_reported_as_what_happened(safe_again, expected, capsys) -> None:
    # A signal that lands after the shot's own end (past the check for a second SAFE) must not
    # be reported as a second SAFE that never ran.
    import argparse

    from hopkinson.rig.cli.shot import _report
    from hopkinson.rig.shot import EXIT_ABORTED, ShotOutcome

    latch = argparse.Namespace(received=signal.SIGHUP, reason="interrupted (SIGHUP)")
    args = argparse.Namespace(json=False, json_events=True)
    assert _report(args, ShotOutcome(final_state="DONE"), None, latch, safe_again) == EXIT_ABORTED
    assert capsys.readouterr().err.strip().splitlines()[-1] == f"hopkinson: error: interrupted (SIGHUP): {expected}"


def test_the_json_exit_code_is_the_exit_code_also_when_the_lab_record_is_lost(capsys) -> None:
    import argparse

    from hopkinson.rig.cli.shot import _report
    from hopkinson.rig.shot import ShotOutcome

    no_signal = argparse.Namespace(received=None, reason="")
    args = argparse.Namespace(json=True, json_events=False)
    assert _report(args, ShotOutcome(final_state="DONE"), None, no_signal, None, record_lost=True) == 5
    assert json.loads(capsys.readouterr().out)["exit_code"] == 5
    failed = ShotOutcome(final_state="DONE", analysis_error="analysis failed: too short", exit_code=4)
    assert _report(args, failed, None, no_signal, None, record_lost=True) == 4  # the analysis says more
    assert json.loads(capsys.readouterr().out)["exit_code"] == 4


def test_every_exit_code_is_in_the_one_table() -> None:
    import hopkinson.rig.errors as errors
    from hopkinson.rig.campaign import EXIT_ANALYSIS_FAILED, EXIT_COMPLETE, EXIT_STOPPED
    from hopkinson.rig.lab_record import EXIT_NOT_RECORDED

    codes = {v for k, v in vars(errors).items() if k.startswith("EXIT_") and isinstance(v, int)}
    codes |= {EXIT_ANALYSIS_FAILED, EXIT_COMPLETE, EXIT_STOPPED, EXIT_NOT_RECORDED}
    assert {str(c) for c in codes} <= set(errors.EXIT_CODES)
    text = (REPO / "docs" / "exit-codes.md").read_text(encoding="utf-8")
    assert all(f"| {code} |" in text for code in errors.EXIT_CODES)
