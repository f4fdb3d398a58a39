"""config/rig.toml and config/sim.toml: typed frozen sections; bad files name file, key and reason."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from hopkinson.drivers.registers import Register
from hopkinson.drivers.sim.accelerometer import Mode
from hopkinson.drivers.sim.controller_map import Point, default_map
from hopkinson.drivers.valve_controller import RegisterMap
from hopkinson.rig.config import load_rig_config, load_sim_config, register_map_of
from hopkinson.rig.errors import ConfigError

CONFIG = Path(__file__).resolve().parents[2] / "config"


def test_shipped_rig_config_loads_into_typed_frozen_sections() -> None:
    config = load_rig_config(CONFIG / "rig.toml")
    assert config.path.endswith("rig.toml")
    assert config.valve_controller.port == 502
    assert isinstance(config.valve_controller.register_map, RegisterMap)
    assert config.valve_controller.register_map.holding_registers.projectile == -1
    assert config.valve_controller.register_map.input_registers.fire_pulse_count == Register(4, "uint32")
    assert config.valve_controller.address == "modbus-tcp://192.168.10.20:502/1"
    assert config.valve_controller.gauge_resolution_bar == 0.001
    assert config.digitizer.sample_rate_hz == 100e6 and isinstance(config.digitizer.sample_rate_hz, float)
    assert config.digitizer.pre_trigger_samples == 20_000  # 0.1 of 200 000
    assert config.amplifier.gain == 10.0
    assert config.timeouts.charge_s == 120.0
    assert config.analysis.orders == (1, -1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.limits.max_pressure_bar = 99.0  # type: ignore[misc]
    json.dumps(config.snapshot())
    assert config.snapshot()["valve_controller"]["coils"]["fire_valve"] == 0


def test_sim_variant_points_at_the_simulator_defaults() -> None:
    rig = load_rig_config(CONFIG / "rig-sim.toml")
    sim = load_sim_config(CONFIG / "sim.toml")
    assert rig.valve_controller.host == sim.servers.host
    assert rig.valve_controller.port == sim.servers.modbus_port
    assert rig.digitizer.resource == f"TCPIP0::{sim.servers.host}::{sim.servers.digitizer_port}::SOCKET"
    assert rig.amplifier.port == "sim:amplifier"  # looked up in the running simulator's addresses file
    assert rig.amplifier.baudrate == sim.servers.amplifier_baudrate
    assert rig.valve_controller.unit_id == sim.servers.modbus_unit_id
    assert rig.valve_controller.register_map == register_map_of(sim.register_map)
    assert sim.register_map == default_map()
    assert sim.world.accelerometer.modes == (Mode(27_000.0, 0.05),)
    assert sim.world.launcher.pulse_width_s == (120e-6, 75e-6, 38.6e-6)
    assert rig.analysis.grating_pitch_m == sim.world.signals.grating_pitch_m
    assert rig.analysis.sensitivity_v_per_m_s2 == sim.world.accelerometer.sensitivity_v_per_m_s2


def edited(tmp_path: Path, source: str, old: str, new: str) -> Path:
    text = (CONFIG / source).read_text()
    assert old in text, old
    path = tmp_path / source
    path.write_text(text.replace(old, new, 1))
    return path


BAD_RIG = [  # (old, new, key, reason): one edit of config/rig.toml and the error it gives
        ("[limits]", "[limit]", "limit", "unknown section in top level"),
        ("port = 502\n", "port = 502\nprot = 5\n", "valve_controller.prot", "unknown key"),
        ("port = 502\n", 'port = "502"\n', "valve_controller.port", "must be an integer, got a string ('502')"),
        ("port = 502\n", "port = 70000\n", "valve_controller.port", "must be at most 65535"),
        ("port = 502\n", "port = true\n", "valve_controller.port", "must be an integer, got a boolean"),
        ("unit_id = 1", "unit_id = 300", "valve_controller.unit_id", "must be at most 247"),
        ('transport = "tcp"', 'transport = "udp"', "valve_controller.transport", "must be one of tcp, rtu"),
        ('transport = "tcp"', 'transport = "rtu"', "valve_controller.serial_port", "missing key"),
        ("fire_valve = 0", "fire_valve = -3", "valve_controller.coils.fire_valve", "must be at least 0"),
        ("fill_valve = 1", "fill_valve = 0", "valve_controller", "coils.fire_valve and coils.fill_valve both use address 0"),
        ("watchdog_state = 2", "watchdog_state = 5",
         "valve_controller", "input_registers.watchdog_state and input_registers.fire_pulse_count both use address 5"),
        ('pressure_setpoint = { address = 0, type = "uint16", scale = 0.001 }',
         'pressure_setpoint = { address = 0, type = "uint16", scale = 0.0 }',
         "valve_controller.holding_registers.pressure_setpoint", "non-zero"),
        ('pressure_setpoint = { address = 0, type = "uint16", scale = 0.001 }',
         'pressure_setpoint = { address = 0, type = "int64" }',
         "valve_controller.holding_registers.pressure_setpoint.type", "must be one of int16, uint16, int32"),
        ('fixture_vacuum = { address = 1, type = "uint16", scale = 0.1 }',
         'fixture_vacuum = { address = 1, type = "float32", word_order = "middle" }',
         "valve_controller.input_registers.fixture_vacuum.word_order", "must be one of big, little"),
        ("heartbeat = 2 ", "heartbeat = -1 ", "valve_controller.holding_registers.heartbeat",
         "the controller's link watchdog and its fire pulse"),
        ("fire_pulse_s = 0.2", "fire_pulse_s = 5.0", "valve_controller.fire_pulse_s",
         "must be shorter than valve_controller.watchdog_s"),
        ("fire_pulse_ms = 4", 'fire_pulse_ms = { address = 4, type = "int16", scale = 0.001 }',
         "valve_controller.fire_pulse_s", "200 ms does not fit valve_controller.holding_registers.fire_pulse_ms"),
        ('host = "192.168.10.20"\n', "", "valve_controller.host", "missing key"),
        ('driver = "modbus"', 'driver = "no_such_lab_module:Controller"', "valve_controller.driver",
         "cannot import 'no_such_lab_module'"),
        ('driver = "modbus"', 'driver = "collections:OrderedDict"', "valve_controller.driver",
         "cannot be the valve controller: it has no __enter__, __exit__, close, connect"),
        ('driver = "modbus"', 'driver = "no-such-entry-point"', "valve_controller.driver",
         "no entry point of group 'hopkinson.drivers'"),
        ('trigger_slope = "POS"', 'trigger_slope = "UP"', "digitizer.trigger_slope", "must be one of POS, NEG"),
        ("sample_rate_hz = 100e6", "sample_rate_hz = nan", "digitizer.sample_rate_hz", "finite"),
        ("record_length = 200000", "record_length = 2.5e5", "digitizer.record_length", "must be an integer"),
        ("gain = 10.0", "gain = 3.0", "amplifier.gain", "the serial bridge amplifier has 1, 2, 5, 10"),
        ("lowpass_hz = 200000.0", "lowpass_hz = 30000.0", "amplifier.lowpass_hz", "the serial bridge amplifier has 0, 1000"),
        ("excitation_v = 5.0", "excitation_v = 12.0", "amplifier.excitation_v", "must be at most 10"),
        ('port = "/dev/ttyUSB0"', 'port = ""', "amplifier.port", "missing key"),
        # thresholds against the limits, the gauge's resolution and the registers (issue 9)
        ("vent_done_bar = 0.05", "vent_done_bar = 9", "limits.vent_done_bar",
         "9 bar must be below limits.min_pressure_bar (0.2 bar)"),
        ("vent_done_bar = 0.05", "vent_done_bar = 0.0001", "limits.vent_done_bar",
         "finer than the reservoir gauge resolves (0.001 bar per count)"),
        ("pressure_tolerance_bar = 0.05", "pressure_tolerance_bar = 9", "limits.pressure_tolerance_bar",
         "9 bar is more than half of limits.min_pressure_bar (0.2 bar)"),
        ("pressure_tolerance_bar = 0.05", "pressure_tolerance_bar = 0.0002", "limits.pressure_tolerance_bar",
         "finer than the reservoir gauge resolves"),
        ("max_pressure_bar = 8.0", "max_pressure_bar = 70.0", "limits.max_pressure_bar",
         "70 bar does not fit valve_controller.holding_registers.pressure_setpoint (uint16, scale 0.001: 0 .. 65.535 bar)"),
        ('reservoir_pressure = { address = 0, type = "uint16", scale = 0.001 }',
         'reservoir_pressure = { address = 0, type = "int16", scale = 0.0001 }', "limits.max_pressure_bar",
         "8 bar does not fit valve_controller.input_registers.reservoir_pressure (int16, scale 0.0001"),
        ('fixture_vacuum = { address = 1, type = "uint16", scale = 0.1 }',
         'fixture_vacuum = { address = 1, type = "int16", scale = 0.001 }', "limits.fixture_vacuum_max_mbar",
         "100 mbar does not fit valve_controller.input_registers.fixture_vacuum (int16, scale 0.001: -32.768 .. 32.767"),
        ("min_pressure_bar = 0.2", "min_pressure_bar = 9.0", "limits.min_pressure_bar",
         "must be below limits.max_pressure_bar"),
        ("charge_s = 120.0", "charge_s = -1.0", "timeouts.charge_s", "must be greater than 0"),
        ("orders = [1, -1]", "orders = [1, 1]", "analysis.orders", "must differ"),
        ("orders = [1, -1]", "orders = [1, -1, 2]", "analysis.orders", "must have 2 items, got 3"),
        ("orders = [1, -1]", 'orders = [1, "-1"]', "analysis.orders[1]", "must be an integer"),
        ("# dcm_widening = 3.0", "dcm_widening = 0.5", "analysis.dcm_widening", "must be greater than 1"),
    ]


@pytest.mark.parametrize(("old", "new", "key", "reason"), BAD_RIG)
def test_bad_rig_config_names_file_key_and_reason(tmp_path: Path, old: str, new: str, key: str, reason: str) -> None:
    path = edited(tmp_path, "rig.toml", old, new)
    with pytest.raises(ConfigError) as caught:
        load_rig_config(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: {key}: "), message
    assert reason in message, message


def test_a_section_given_as_a_value(tmp_path: Path) -> None:
    text = (CONFIG / "rig.toml").read_text()
    path = tmp_path / "rig.toml"
    path.write_text("timeouts = 5\n" + text.replace("[timeouts]", "[unused_timeouts]").split("[unused_timeouts]")[0]
                    + text[text.index("[analysis]"):])
    with pytest.raises(ConfigError, match=r"rig.toml: timeouts: must be a table, got an integer \(5\)"):
        load_rig_config(path)


def test_missing_section_file_and_toml_syntax(tmp_path: Path) -> None:
    text = (CONFIG / "rig.toml").read_text()
    start = text.index("[amplifier]")
    no_amp = tmp_path / "no-amp.toml"
    no_amp.write_text(text[:start] + text[text.index("[limits]"):])
    with pytest.raises(ConfigError, match=r"no-amp.toml: amplifier: missing section"):
        load_rig_config(no_amp)
    with pytest.raises(ConfigError, match=r"absent.toml: no such file"):
        load_rig_config(tmp_path / "absent.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("[valve_controller\nhost = 1\n")
    with pytest.raises(ConfigError, match=r"broken.toml: not valid TOML"):
        load_rig_config(broken)


LIMITS = ('[limits]\nmax_pressure_bar = 6.0\nmin_pressure_bar = 0.2\npressure_tolerance_bar = 0.05\n'
          'fixture_vacuum_max_mbar = 100.0\nvent_done_bar = 0.05\n')


def test_minimal_rig_config_takes_documented_defaults(tmp_path: Path) -> None:
    path = tmp_path / "minimal.toml"
    path.write_text('[valve_controller]\nhost = "10.0.0.5"\n[digitizer]\nresource = "TCPIP0::10.0.0.6::5025::SOCKET"\n'
                    '[amplifier]\nport = "/dev/ttyS0"\n' + LIMITS)  # the safety limits are never defaults
    config = load_rig_config(path)
    assert config.valve_controller.port == 502 and config.valve_controller.register_map == RegisterMap()
    assert config.valve_controller.watchdog_s == 3.0 and config.valve_controller.fire_pulse_s == 0.2
    assert config.digitizer.trigger_source == "CH2"
    assert config.limits.max_pressure_bar == 6.0


def test_modbus_rtu_and_a_manual_conditioner(tmp_path: Path) -> None:
    path = tmp_path / "rtu.toml"
    path.write_text('[valve_controller]\ntransport = "rtu"\nserial_port = "/dev/ttyUSB1"\nbaudrate = 9600\n'
                    'parity = "E"\nunit_id = 17\n'
                    '[valve_controller.input_registers]\n'
                    'reservoir_pressure = { address = 10, type = "float32", word_order = "little" }\n'
                    '[digitizer]\nresource = "TCPIP0::10.0.0.6::5025::SOCKET"\n'
                    '[amplifier]\ndriver = "manual"\ngain = 3.16\nexcitation_v = 0.0\nlowpass_hz = 30000.0\n'
                    'sensitivity_v_per_m_s2 = 1.2e-5\nidentity = "Kistler 5015A, SN 123"\n' + LIMITS)
    config = load_rig_config(path)
    vc = config.valve_controller
    assert vc.address == "modbus-rtu:///dev/ttyUSB1/17"
    assert (vc.target.baudrate, vc.target.parity, vc.target.byte_time_s) == (9600, "E", pytest.approx(11 / 9600))
    assert vc.register_map.input_registers.reservoir_pressure == Register(10, "float32", "little")
    assert vc.gauge_resolution_bar == 0.0  # a float gauge: no count to round to
    assert config.amplifier.driver == "manual" and config.amplifier.gain == 3.16  # any gain: set by hand


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (b"\x89HDF\r\n\x1a\n\x00\xff\xfe binary", "not UTF-8 text (byte 0): is it a binary file?"),
        (b"[valve_controller]\nhost = \"\xe9\"\n", "not UTF-8 text (byte 27): is it a binary file?"),
    ],
)
def test_a_binary_rig_file_is_one_line(tmp_path: Path, content: bytes, reason: str) -> None:
    path = tmp_path / "rig.toml"
    path.write_bytes(content)
    with pytest.raises(ConfigError) as caught:
        load_rig_config(path)
    assert str(caught.value) == f"{path}: {reason}"


def test_a_folder_or_a_device_is_not_a_config(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="is a folder"):
        load_rig_config(tmp_path)
    with pytest.raises(ConfigError, match="/dev/zero: not a regular file"):
        load_rig_config("/dev/zero")


def test_a_named_pipe_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    import os
    import threading

    fifo = tmp_path / "rig.toml"
    os.mkfifo(fifo)
    errors: list[str] = []
    reader = threading.Thread(target=lambda: errors.append(_config_error(fifo)), daemon=True)
    reader.start()
    reader.join(30.0)  # opening a pipe for reading would block until a writer came: it must not
    assert not reader.is_alive(), "load_rig_config waited on a named pipe"
    assert errors == [f"{fifo}: not a regular file (a device, pipe or socket), not a configuration file"]


def _config_error(path: Path) -> str:
    try:
        load_rig_config(path)
    except ConfigError as exc:
        return str(exc)
    return "no error"


BAD_SIM = [  # (old, new, key, reason): one edit of config/sim.toml and the error it gives
        ("time_scale = 10.0", "time_scale = 0.0", "world.time_scale", "must be greater than 0"),
        ("projectile = 3", "projectile = 4", "world.launcher.projectile", "must be one of 1, 2, 3"),
        ("pulse_width_s = [120e-6, 75e-6, 38.6e-6]", "pulse_width_s = [120e-6, 75e-6]",
         "world.launcher.pulse_width_s", "must have 3 items"),
        ("damping_ratio = 0.05", "damping_ratio = -0.05", "world.accelerometer.modes[0].damping_ratio",
         "must be greater than 0"),
        ("natural_frequency_hz = 27000.0", "natural_frequency_hz = 27000.0\nq = 3",
         "world.accelerometer.modes[0].q", "unknown key"),
        ("modbus_port = 5020", "modbus_port = 65536", "servers.modbus_port", "must be at most 65535"),
        ("door_closed = true", "door_closed = 1", "world.pneumatics.door_closed", "must be true or false"),
        ("pm_snr_db = 30.0", "pm_snr_db = -5.0", "world.signals.pm_snr_db", "0 (no noise)"),
        ("orders = [1, -1]", "orders = [2, 2]", "world.signals.orders", "must differ"),
    ]


@pytest.mark.parametrize(("old", "new", "key", "reason"), BAD_SIM)
def test_bad_sim_config_names_file_key_and_reason(tmp_path: Path, old: str, new: str, key: str, reason: str) -> None:
    path = edited(tmp_path, "sim.toml", old, new)
    with pytest.raises(ConfigError) as caught:
        load_sim_config(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: {key}: "), message
    assert reason in message, message


def test_sim_register_map_override(tmp_path: Path) -> None:
    path = tmp_path / "sim.toml"
    path.write_text('[servers]\nmodbus_transport = "rtu"\nmodbus_baudrate = 9600\n'
                    "[register_map.coils]\nfire_valve = 8\n[register_map.input_registers]\n"
                    'fixture_vacuum = { address = 1, type = "float32", scale = 1.0 }\nwatchdog_state = 7\n')
    config = load_sim_config(path)
    assert config.servers.modbus_transport == "rtu" and config.servers.modbus_baudrate == 9600
    assert config.register_map["coils"]["fire_valve"] == Point(8)
    assert config.register_map["coils"]["fill_valve"] == Point(1)
    assert config.register_map["input_registers"]["fixture_vacuum"] == Point(1, "float32")
    overlap = tmp_path / "overlap.toml"
    overlap.write_text('[register_map.input_registers]\nfixture_vacuum = { address = 1, type = "float32" }\n')
    with pytest.raises(ConfigError, match="input_registers.fixture_vacuum and input_registers.watchdog_state both "
                                          "use address 2"):
        load_sim_config(overlap)


def test_the_readmes_instruments_example_loads(tmp_path: Path) -> None:
    section = (CONFIG.parent / "docs" / "instruments.md").read_text(encoding="utf-8")
    example = section[section.index("```toml\n") + 8:section.index("```\n", section.index("```toml"))]
    text = (CONFIG / "rig.toml").read_text()
    path = tmp_path / "rig.toml"
    path.write_text(example + text[text.index("[digitizer]"):])
    vc = load_rig_config(path).valve_controller
    assert vc.address == "modbus-rtu:///dev/ttyUSB1/17"
    assert vc.register_map.input_registers.reservoir_pressure == Register(0, "int32", "little", 1e-4)


@pytest.mark.parametrize("source", ["rig.toml", "rig-sim.toml"])
@pytest.mark.parametrize("drop, named", [
    ("section", "[limits]"),
    ("max_pressure_bar", "limits.max_pressure_bar"),
    ("vent_done_bar", "limits.vent_done_bar"),
])
def test_a_rig_file_must_state_its_safety_limits(tmp_path: Path, source: str, drop: str, named: str) -> None:
    # issue 18: a config without [limits] loaded silently and fired with built-in limits (8 bar)
    import re

    text = (CONFIG / source).read_text(encoding="utf-8")
    if drop == "section":
        text, n = re.subn(r"^\[limits\][^\[]*", "", text, flags=re.M)
    else:
        text, n = re.subn(rf"^{drop} = .*$", "", text, flags=re.M)
    assert n == 1
    path = tmp_path / "rig.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_rig_config(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {named}: the rig must state its safety limits")
    assert (f"{drop} = …" in message) if drop != "section" else ("max_pressure_bar = …" in message)
    load_rig_config(CONFIG / source)  # the shipped files state them


@pytest.mark.parametrize(("lab", "key", "reason"), [
    ('[[lab.reference_chain]]\nitem = "grating"\ncertificate = "C-1"\nbudget = "grating_rel"\n',
     "lab.reference_chain[0].budget", "one of grating_pitch_rel, interferometer_rel, amplifier_gain_rel"),
    ('[[lab.signatories]]\nname = "A. Head"\nrole = " "\n', "lab.signatories[0].role", "must not be empty"),
    ('[[lab.signatories]]\nname = "A. Head"\n', "lab.signatories[0].role", "missing key"),
    ('[lab]\ncountry = "Germany"\n', "lab.country", 'an ISO 3166-1 alpha-2 code such as "DE"'),
])
def test_the_labs_signatories_country_and_budget_inputs_are_checked(tmp_path: Path, lab: str, key: str,
                                                                   reason: str) -> None:
    path = tmp_path / "rig.toml"
    path.write_text((CONFIG / "rig.toml").read_text() + lab)
    with pytest.raises(ConfigError) as caught:
        load_rig_config(path)
    assert str(caught.value).startswith(f"{path}: {key}: ") and reason in str(caught.value), str(caught.value)
    good = ('[lab]\ncountry = "DE"\n[[lab.signatories]]\nname = "A. Head"\nrole = "head of lab"\n'
            '[[lab.reference_chain]]\nitem = "grating"\ncertificate = "C-1"\nbudget = "grating_pitch_rel"\n')
    path.write_text((CONFIG / "rig.toml").read_text() + good)
    lab_config = load_rig_config(path).lab
    assert lab_config.country == "DE" and lab_config.signatories[0].role == "head of lab"
    assert lab_config.reference_chain[0].budget == "grating_pitch_rel"
