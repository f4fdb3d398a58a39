"""`hopkinson sim` (as its own process, once) and `hopkinson status`."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hopkinson.drivers.sim.faults import FAULTS
from hopkinson.drivers.sim.simulated_rig import SimAddresses, SimulatedRig
from hopkinson.rig.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"


def rig_toml_for(addresses: SimAddresses | dict, tmp_path: Path, name: str = "rig.toml") -> Path:
    """config/rig-sim.toml with the addresses of a simulator started on free ports."""
    a = addresses.as_dict() if isinstance(addresses, SimAddresses) else addresses
    text = (CONFIG / "rig-sim.toml").read_text()
    replacements = {
        "port = 5020\n": f"port = {a['modbus_port']}\n",
        'resource = "TCPIP0::127.0.0.1::5025::SOCKET"': f'resource = "{a["visa_resource"]}"',
        'port = "/tmp/hopkinson-sim-amplifier"': f'port = "{a["serial_port"]}"',
    }
    for old, new in replacements.items():
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return path


def test_list_faults_prints_one_line_per_fault(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--list-faults"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(FAULTS)
    for line, (name, text) in zip(lines, FAULTS.items(), strict=True):
        assert line.split()[0] == name and line.endswith(text)


def test_unknown_fault_and_bad_config_are_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--fault", "gremlins"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown fault 'gremlins'" in err and "modbus-slow" in err
    bad = tmp_path / "sim.toml"
    bad.write_text("[world]\ntime_scale = -1\n")
    assert main(["sim", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err == f"hopkinson: error: {bad}: world.time_scale: must be greater than 0, got -1\n"


def test_sim_process_serves_status_and_stops_cleanly_on_ctrl_c(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sim_toml = tmp_path / "sim.toml"
    link = tmp_path / "amplifier-link"
    sim_toml.write_text(f'[servers]\nmodbus_port = 0\ndigitizer_port = 0\nserial_link = "{link}"\n')
    addresses_json = tmp_path / "addresses.json"
    process = subprocess.Popen(
        [sys.executable, "-m", "hopkinson", "sim", "--config", str(sim_toml), "--fault", "door-open",
         "--addresses-json", str(addresses_json)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        deadline = time.monotonic() + 30.0
        while not addresses_json.exists():
            assert process.poll() is None, process.communicate()
            assert time.monotonic() < deadline, "the simulator did not write its addresses"
            time.sleep(0.05)
        addresses = json.loads(addresses_json.read_text())
        assert addresses["pid"] == process.pid
        assert os.path.realpath(link) == addresses["serial_port"]
        config = rig_toml_for(addresses, tmp_path)
        assert main(["status", "--config", str(config), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
        assert report["ok"] is True
        assert report["valve_controller"]["identity"] == "Hopkinson-Sim,SIMVAC-1,1.0"
        assert report["valve_controller"]["interlock_problems"] == ["door/guard open"]  # --fault door-open
        assert report["digitizer"]["identity"].startswith("Hopkinson-Sim,SIMDIG")
        assert report["amplifier"]["identity"].startswith("Hopkinson-Sim,SIMAMP")
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=15)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, err
    assert f"modbus  {addresses['modbus']}\n" in out
    assert f"visa    {addresses['visa_resource']}\n" in out
    assert f"serial  {addresses['serial_port']} (link {link})\n" in out
    assert "faults  door-open" in out and out.endswith("simulated rig stopped\n")
    assert "Traceback" not in err
    assert not link.exists()
    for port in (addresses["modbus_port"], int(addresses["visa_resource"].split("::")[2])):
        with socket.socket() as s:
            assert s.connect_ex(("127.0.0.1", port)) != 0


def test_status_reports_every_instrument_of_an_in_process_rig(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedRig() as sim:
        sim.world.set_pressure_setpoint_bar(2.5)
        config = rig_toml_for(sim.addresses, tmp_path)
        assert main(["status", "--config", str(config)]) == 0
        text = capsys.readouterr().out
        assert main(["status", "--config", str(config), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
    assert "valve/vacuum controller" in text and "(set-point 2.500 bar)" in text
    assert "interlocks         all safe" in text and "all instruments answered" in text
    assert report["valve_controller"]["pressure_setpoint_bar"] == pytest.approx(2.5)
    assert report["valve_controller"]["fixture_vacuum_mbar"] == pytest.approx(1013.2, abs=0.1)
    assert report["valve_controller"]["valves"] == {"fire_valve": False, "fill_valve": False,
                                                    "vent_valve": False, "vacuum_pump": False}
    assert report["digitizer"]["state"] == "IDLE"
    assert report["amplifier"]["gain"] == 10.0 and report["amplifier"]["overloaded"] is False


def test_status_reports_missing_instruments_without_crashing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as a, socket.socket() as b:  # bound, not listening: connection refused
        a.bind(("127.0.0.1", 0))
        b.bind(("127.0.0.1", 0))
        addresses = {"modbus_port": a.getsockname()[1],
                     "visa_resource": f"TCPIP0::127.0.0.1::{b.getsockname()[1]}::SOCKET",
                     "serial_port": str(tmp_path / "no-such-tty")}
        config = rig_toml_for(addresses, tmp_path)
        assert main(["status", "--config", str(config), "--json"]) == 1
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    assert report["ok"] is False
    for key in ("valve_controller", "digitizer", "amplifier"):
        assert report[key]["ok"] is False and report[key]["error"]
    assert "'connect': could not connect" in report["valve_controller"]["error"]
    assert "digitizer" in report["digitizer"]["error"]
    assert "no-such-tty" in report["amplifier"]["error"]
    assert captured.err == ""


def test_status_with_a_bad_config_is_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "rig.toml"
    bad.write_text((CONFIG / "rig.toml").read_text().replace("retries = 0", "retries = many"))
    assert main(["status", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"hopkinson: error: {bad}: not valid TOML") and err.count("\n") == 1


def test_sim_on_a_busy_port_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        sim_toml = tmp_path / "sim.toml"
        sim_toml.write_text(f'[servers]\nmodbus_port = 0\ndigitizer_port = {port}\nserial_link = ""\n')
        assert main(["sim", "--config", str(sim_toml)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"hopkinson: error: cannot start the simulated rig ({sim_toml}):")
    assert err.count("\n") == 1 and "Address already in use" in err
