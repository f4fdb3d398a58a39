"""Whole shots in every fire style a PLC uses (docs/plc-fire-styles.md), over Modbus TCP on
loopback and Modbus RTU on a pty, against the simulated controller set to that style; and what
the sequencer says when the configured style is not the PLC's: "not fired", never "fired"."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import pytest

from hopkinson.drivers.sim.controller_map import Point, default_map
from hopkinson.drivers.sim.simulated_rig import SimConfig
from hopkinson.rig.config import RigConfig, load_rig_config
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.events import Fired
from tests.rig.conftest import REPO, fast_sim_config, short_timeouts_config

# style -> the extra signals its PLC has (a fire coil of its own, a command word)
STYLES: dict[str, dict[str, int]] = {
    "pulse_register": {},
    "preset_and_coil": {"fire_command": 6},
    "preset_and_command": {"fire_command_word": 7},
    "plc_preset_coil": {},  # the fire valve's coil is the fire coil
    "host_timed_coil": {},
}
COUNTER = "the controller's pulse counter (0 → 1)"


def styled(style: str, transport: str = "tcp", *, counter: bool = True, position: bool = True,
           **signals: int) -> SimConfig:
    """The fast simulated rig whose controller fires in `style`."""
    base = fast_sim_config()
    layout = default_map()
    signals = signals or STYLES[style]
    if "fire_command" in signals:
        layout["coils"]["fire_command"] = Point(signals["fire_command"])
    if "fire_command_word" in signals:
        layout["holding_registers"]["fire_command"] = Point(signals["fire_command_word"])
    if not counter:
        del layout["input_registers"]["fire_pulse_count"]
    if not position:
        del layout["discrete_inputs"]["fire_valve_open"]
    servers = replace(base.servers, modbus_transport=transport, modbus_baudrate=115200, modbus_fire_style=style,
                      modbus_fire_command_value=0x00F1)
    return replace(base, servers=servers, register_map=layout)


def patient(config: RigConfig) -> RigConfig:
    """A controller timeout of 1.5 s for a test that is not about timeouts: the conftest's 0.4 s
    missed one RTU reply on a loaded CI machine (3 workers on 2 cores, pty relay thread starved)."""
    return dataclasses.replace(config, valve_controller=dataclasses.replace(config.valve_controller, timeout_s=1.5))


def with_style(style: str) -> object:
    def adjust(config: RigConfig) -> RigConfig:
        return dataclasses.replace(config, valve_controller=dataclasses.replace(
            config.valve_controller, fire_style=style, host_timed_fire_allowed=style == "host_timed_coil"))
    return adjust


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
@pytest.mark.parametrize("style", list(STYLES))
def test_a_shot_fires_in_each_style(make_rig, style: str, transport: str) -> None:
    rig = make_rig(sim=styled(style, transport), heartbeat=True, adjust=patient)
    assert rig.config.valve_controller.fire_style == style and rig.config.valve_controller.transport == transport
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.final_state == "DONE" and outcome.exit_code == 0 and outcome.fired, outcome.error
    fired = rig.recorder.of(Fired)
    assert len(fired) == 1 and rig.world.shots_fired == 1
    if style == "host_timed_coil":  # the simulated PLC counts only the pulses it times itself
        assert rig.world.fire_pulses == 0 and fired[0].confirmed_by == "the fire valve's read-back"
        assert "timed by this computer" in fired[0].message
    else:
        assert rig.world.fire_pulses == 1 and fired[0].confirmed_by == COUNTER
    # the pulse recorded is the one fired: the PLC's own preset where it keeps one (sim default 150 ms)
    assert fired[0].pulse_s == pytest.approx(0.15 if style == "plc_preset_coil" else 0.2)
    rig.assert_safe()


def test_host_timed_fire_without_a_heartbeat_is_refused_before_the_valve_moves(make_rig) -> None:
    rig = make_rig(sim=styled("host_timed_coil"))  # no heartbeat session: no watchdog backs the host
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.aborted_in == "FIRE" and outcome.exit_code == 3
    assert "a pulse timed by this computer is refused: no heartbeat runs" in outcome.error
    assert not outcome.fired and rig.world.shots_fired == 0 and not rig.recorder.of(Fired)
    rig.assert_safe()


@pytest.mark.parametrize("plc", ["preset_and_coil", "preset_and_command", "plc_preset_coil"])
def test_the_wrong_fire_style_is_not_fired_and_says_so_at_once(make_rig, plc: str) -> None:
    """The issue's case: the PLC wants a preset and then a coil (or a command word), the rig is
    configured for today's style and writes the preset only. Its counter stays, its valve reads
    back shut, the digitizer does not trigger: FIRE says "not fired", names the style, and does
    not wait for a trigger that cannot come."""
    rig = make_rig(sim=styled(plc), adjust=with_style("pulse_register"), heartbeat=True)
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.aborted_in == "FIRE" and outcome.final_state == "ABORTED" and outcome.exit_code == 3
    assert ("not fired: the PLC did not start the pulse (its pulse count stayed at 0, the fire valve read back shut, "
            "the digitizer did not trigger): check the fire style: fire_style = \"pulse_register\" writes the pulse "
            "length to holding register 4 and expects that write to start the pulse") in outcome.error
    assert "docs/plc-fire-styles.md" in outcome.hint and "the shot was fired" not in outcome.error
    assert outcome.fired is False and not rig.recorder.of(Fired)
    assert rig.world.shots_fired == 0 and rig.world.fire_pulses == 0
    rig.assert_safe()


def test_a_fire_coil_the_plcs_program_ignores_is_not_fired_either(make_rig) -> None:
    """The PLC fires on a command word; its coil 6 is a memory bit no program reads."""
    rig = make_rig(sim=styled("preset_and_command", fire_command=6, fire_command_word=7),
                   adjust=with_style("plc_preset_coil"), heartbeat=True)
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.aborted_in == "FIRE" and "not fired: the PLC did not start the pulse" in outcome.error
    assert 'fire_style = "plc_preset_coil" switches on coil 6 and expects the PLC to time the pulse' in outcome.error
    assert rig.world.shots_fired == 0 and not outcome.fired
    rig.assert_safe()


def test_without_counter_or_valve_read_back_the_trigger_confirms_the_shot(make_rig) -> None:
    """A PLC with no pulse counter and no valve position input, fired on the fire valve's own
    coil: nothing but the digitizer's trigger can tell that the shot went."""
    rig = make_rig(sim=styled("plc_preset_coil", counter=False, position=False), heartbeat=True)
    assert not rig.instruments.valves.has_pulse_counter
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.final_state == "DONE", outcome.error
    fired = rig.recorder.of(Fired)
    assert len(fired) == 1 and fired[0].confirmed_by == "the digitizer's trigger"
    rig.assert_safe()


def test_without_any_witness_a_missing_trigger_never_claims_a_fire(make_rig) -> None:
    config = short_timeouts_config(capture_s=0.5)
    rig = make_rig(sim=styled("plc_preset_coil", counter=False, position=False), config=config,
                   faults=("no-trigger",), heartbeat=True)
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.aborted_in == "CAPTURE" and outcome.exit_code == 3
    assert "the fire command was sent but nothing confirms a shot" in outcome.error
    assert "the shot was fired" not in outcome.error and not rig.recorder.of(Fired)
    assert outcome.fired  # the command went out: a campaign asks the operator (UNKNOWN), never refires on its own
    rig.assert_safe()


# -- the fire style in rig.toml -------------------------------------------------------------------------
def rig_toml_with(tmp_path, *edits: tuple[str, str]):
    text = (REPO / "config" / "rig-sim.toml").read_text(encoding="utf-8")
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    path = tmp_path / "rig.toml"
    path.write_text(text, encoding="utf-8")
    return path


STYLE_LINE = 'fire_style = "pulse_register"'


@pytest.mark.parametrize(("edits", "message"), [
    ([(STYLE_LINE, 'fire_style = "pulse"')],
     r"valve_controller.fire_style: .*pulse_register, preset_and_coil, preset_and_command, plc_preset_coil, "
     r"host_timed_coil"),
    ([(STYLE_LINE, 'fire_style = "preset_and_command"')],
     r"valve_controller.holding_registers.fire_command: missing: valve_controller.fire_style = "
     r"\"preset_and_command\" \(docs/plc-fire-styles.md\) starts the pulse by writing "
     r"valve_controller.fire_command_value \(1\) there"),
    ([(STYLE_LINE, 'fire_style = "preset_and_coil"'), ("fire_pulse_ms = 4 ", "fire_pulse_ms = -1 ")],
     r"valve_controller.holding_registers.fire_pulse_ms: missing: .*writes the pulse length there"),
    ([(STYLE_LINE, 'fire_style = "host_timed_coil"')],
     r"valve_controller.host_timed_fire_allowed: .*if it stops mid-pulse the valve stays open until the "
     r"controller's link watchdog closes it \(3 s\): set host_timed_fire_allowed = true only if the lab accepts"),
    ([(STYLE_LINE, STYLE_LINE + "\nhost_timed_fire_allowed = true")],
     r"valve_controller.host_timed_fire_allowed: only for fire_style = \"host_timed_coil\""),
    ([("fire_pulse_count = { address = 4, type = \"uint32\" }", "fire_pulse_count = -1")],
     r"valve_controller.input_registers.fire_pulse_count: missing"),
])
def test_the_fire_style_is_checked_on_load(tmp_path, edits, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_rig_config(rig_toml_with(tmp_path, *edits))


def test_each_style_loads_with_what_it_needs(tmp_path) -> None:
    coil = load_rig_config(rig_toml_with(
        tmp_path, (STYLE_LINE, 'fire_style = "plc_preset_coil"'), ("fire_pulse_ms = 4 ", "fire_pulse_ms = -1 "),
        ("fire_pulse_count = { address = 4, type = \"uint32\" }", "fire_pulse_count = -1"),
        ("vacuum_pump = 3\n", "vacuum_pump = 3\nfire_command = 12\n")))
    assert coil.valve_controller.fire_style == "plc_preset_coil"  # no preset, no counter: the PLC keeps both
    assert coil.valve_controller.register_map.coils.fire_command == 12
    word = load_rig_config(rig_toml_with(
        tmp_path, (STYLE_LINE, 'fire_style = "preset_and_command"\nfire_command_value = 42'),
        ("fire_pulse_ms = 4 ", "fire_pulse_ms = 4 \nfire_command = 7 ")))
    assert word.valve_controller.register_map.holding_registers.fire_command == 7
    assert word.valve_controller.fire_command_value == 42
    host = load_rig_config(rig_toml_with(
        tmp_path, (STYLE_LINE, 'fire_style = "host_timed_coil"\nhost_timed_fire_allowed = true')))
    assert host.valve_controller.host_timed_fire_allowed is True
    assert host.snapshot()["valve_controller"]["fire_style"] == "host_timed_coil"  # recorded with every shot


def test_every_example_in_the_fire_styles_page_loads_as_it_says(tmp_path) -> None:
    """docs/plc-fire-styles.md, run: each TOML example, put into config/rig-sim.toml, is a valid
    rig configuration firing in the style it names."""
    import re
    import tomllib

    import tomli_w

    page = (REPO / "docs" / "plc-fire-styles.md").read_text(encoding="utf-8")
    examples = re.findall(r"```toml\n(.*?)```", page, flags=re.S)
    assert len(examples) == len(STYLES)

    def merged(base: dict, extra: dict) -> dict:
        out = dict(base)
        for key, value in extra.items():
            into = base.get(key)
            out[key] = merged(into, value) if isinstance(value, dict) and isinstance(into, dict) else value
        return out

    base = tomllib.loads((REPO / "config" / "rig-sim.toml").read_text(encoding="utf-8"))
    named = []
    for i, example in enumerate(examples):
        data = tomllib.loads(example)
        path = tmp_path / f"example-{i}.toml"
        path.write_text(tomli_w.dumps(merged(base, data)), encoding="utf-8")
        config = load_rig_config(path)
        assert config.valve_controller.fire_style == data["valve_controller"]["fire_style"]
        named.append(config.valve_controller.fire_style)
    assert sorted(named) == sorted(STYLES)
