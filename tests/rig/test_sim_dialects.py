"""The simulated rig in any digitizer dialect: sim.toml's `servers.digitizer_dialect` (or
`hopkinson sim --digitizer-dialect`) picks the simulated digitizer's command set, and `--sim`
points the rig config at it (dialect and channel names by role) by itself. A shot fires in each
dialect over the real protocol; the `visa-endless-reply` fault (a digitizer that streams a reply
without its terminator) ends a charged shot in ARM with one instrument error and the rig safe."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from hopkinson.drivers.sim.scpi_digitizer import SIM_DIALECTS
from hopkinson.drivers.sim.simulated_rig import ServerParams, SimConfig
from hopkinson.drivers.sim.world import WorldParams
from hopkinson.rig.cli.main import main
from hopkinson.rig.config import ConfigError, load_sim_config
from hopkinson.rig.events import RigError, RigWarning
from hopkinson.rig.instruments import open_instruments
from hopkinson.rig.shotfile import read_shot
from hopkinson.rig.sim_session import sim_session
from tests.rig.conftest import TIME_SCALE, Rig, short_timeouts_config
from tests.rig.test_cli_sim import rig_toml_for, sim_process, stop_with_ctrl_c

REPO = Path(__file__).resolve().parents[2]
IDENTITY = {"generic": "Hopkinson-Sim", "keysight": "KEYSIGHT", "tektronix": "TEKTRONIX", "lecroy": "LECROY"}
NAMES = {"generic": ("CH1", "CH2"), "keysight": ("CHAN1", "CHAN2"), "tektronix": ("CH1", "CH2"),
         "lecroy": ("C1", "C2")}


@contextlib.contextmanager
def dialect_rig(tmp_path: Path, dialect: str, faults: tuple[str, ...] = ()) -> Iterator[Rig]:
    """The tests' in-process rig (tests/rig/conftest.py) with its digitizer in `dialect`."""
    sim = SimConfig(world=WorldParams(time_scale=TIME_SCALE), servers=ServerParams(digitizer_dialect=dialect))
    base = short_timeouts_config()
    base = dataclasses.replace(base, digitizer=dataclasses.replace(base.digitizer, record_length=40_000))
    with sim_session(base, sim, faults) as session, \
            open_instruments(session.config, session.simulated_truth) as instruments:
        yield Rig(session, instruments, tmp_path)


@pytest.mark.parametrize("dialect", tuple(SIM_DIALECTS))
def test_a_shot_fires_in_each_dialect_of_the_simulated_digitizer(tmp_path: Path, dialect: str) -> None:
    with dialect_rig(tmp_path, dialect) as rig:
        digitizer = rig.config.digitizer
        assert (digitizer.dialect, digitizer.channels) == (dialect, dict(zip(("doppler", "response"),
                                                                              NAMES[dialect], strict=True)))
        outcome = rig.run(pressure_bar=1.0)
        rig.assert_safe()
    assert outcome.final_state == "DONE", outcome.error
    shot = read_shot(outcome.shot_path)
    assert shot.meta.instruments["digitizer"].startswith(IDENTITY[dialect])
    assert shot.meta.config["digitizer"]["dialect"] == dialect
    assert shot.raw.trigger_index == 4_000  # 10 % pre-trigger, in every dialect's own units
    response = shot.raw.volts("response")
    assert response.size == 40_000 and response[3_999] < 0.2 <= response[4_000] + 0.01  # on the trigger
    assert np.ptp(shot.raw.volts("doppler")) > 0.3  # the beat is on the doppler role's channel


def test_hopkinson_shot_sim_in_a_dialect_from_the_sim_config(tmp_path: Path, capsys) -> None:
    """The command line: nothing in the rig config names the dialect; --sim takes it from sim.toml."""
    sim = tmp_path / "sim.toml"
    sim.write_text('[servers]\ndigitizer_dialect = "keysight"\n[world]\ntime_scale = 100.0\n', encoding="utf-8")
    rc = main(["shot", "--sim", "--sim-config", str(sim), "--out", str(tmp_path), "--pressure-bar", "1.0",
               "--yes", "--json", "--no-uncertainty", "--dcm-ratio", "7.5", "--max-order", "6"])
    result = json.loads(capsys.readouterr().out)
    assert rc == 0 and result["final_state"] == "DONE", result["error"]
    shot = read_shot(result["shot_path"])
    assert shot.meta.instruments["digitizer"].startswith("KEYSIGHT")
    assert shot.meta.config["digitizer"]["channels"] == {"doppler": "CHAN1", "response": "CHAN2"}
    assert shot.results["params"]["dcm_ratio"] == 7.5 and result["sim_state"]["shots_fired"] == 1


@pytest.mark.timeout(120)  # the reply never ends: a driver that kept reading would hang here
@pytest.mark.parametrize("dialect", ["generic", "lecroy"])
def test_an_endless_reply_aborts_the_armed_shot_safe_with_one_instrument_error(tmp_path: Path, dialect: str) -> None:
    with dialect_rig(tmp_path, dialect, faults=("visa-endless-reply",)) as rig:
        outcome = rig.run(pressure_bar=1.0)
        rig.assert_safe(digitizer=False)  # it hangs: SAFE cannot disarm it, and says so
        assert any(w.message.startswith("SAFE could not disarm the digitizer") for w in rig.recorder.of(RigWarning))
        assert rig.world.shots_fired == 0 and rig.world.fire_pulses == 0
        errors = rig.recorder.of(RigError)
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == "ARM" and outcome.exit_code == 3
    assert not outcome.fired and outcome.safe_confirmed
    assert len(errors) == 1 and errors[0].source == rig.instruments.digitizer.instrument
    assert "reply longer than 65536 bytes" in errors[0].message and "\n" not in outcome.error


def test_hopkinson_shot_sim_with_an_endless_reply_exits_3_with_one_line(tmp_path: Path) -> None:
    sim = tmp_path / "sim.toml"
    sim.write_text('[servers]\ndigitizer_dialect = "tektronix"\n[world]\ntime_scale = 100.0\n', encoding="utf-8")
    state = tmp_path / "state.json"
    done = subprocess.run([sys.executable, "-m", "hopkinson", "shot", "--sim", "--sim-config", str(sim),
                           "--sim-fault", "visa-endless-reply", "--sim-state-file", str(state), "--out", str(tmp_path),
                           "--pressure-bar", "1.0", "--yes", "--json"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 3, done.stderr
    assert done.stderr.count("\n") == 1 and done.stderr.startswith("hopkinson: error: shot aborted in ARM: digitizer")
    assert "reply longer than" in done.stderr and "Traceback" not in done.stderr
    final = json.loads(state.read_text(encoding="utf-8"))
    assert final["fill_valve_open"] is False and final["vent_valve_open"] is True and final["shots_fired"] == 0
    assert final["reservoir_pressure_bar"] <= 0.05


def test_the_sim_configs_dialect_is_checked_on_load(tmp_path: Path) -> None:
    path = tmp_path / "sim.toml"
    path.write_text('[servers]\ndigitizer_dialect = "rigol"\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"servers.digitizer_dialect: must be one of generic, keysight, "
                                          r"tektronix, lecroy, got 'rigol'"):
        load_sim_config(path)
    assert load_sim_config(REPO / "config" / "sim.toml").servers.digitizer_dialect == "generic"


def test_hopkinson_sim_in_a_dialect_prints_the_rig_config_that_reaches_it(tmp_path: Path, capsys,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    runtime = tmp_path / "runtime"
    runtime.mkdir(mode=0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    sim = tmp_path / "sim.toml"
    sim.write_text("[servers]\nmodbus_port = 0\ndigitizer_port = 0\n", encoding="utf-8")
    with sim_process(["--config", str(sim), "--digitizer-dialect", "lecroy"], tmp_path / "addresses.json") \
            as (process, addresses):
        assert addresses["digitizer_dialect"] == "lecroy" and addresses["digitizer_channels"] == {"doppler": 1,
                                                                                                  "response": 2}
        rig = rig_toml_for(addresses, tmp_path)
        text = rig.read_text().replace('dialect = "generic"', 'dialect = "lecroy"')
        text = re.sub(r'^doppler = "CH1"', 'doppler = "C1"', text, count=1, flags=re.M)
        rig.write_text(re.sub(r'^response = "CH2"', 'response = "C2"', text, count=1, flags=re.M))
        assert main(["status", "--config", str(rig), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["digitizer"]["identity"].startswith("LECROY")
        out, err = stop_with_ctrl_c(process)
    assert process.returncode == 0, err
    assert "        lecroy dialect: doppler on channel 1, response on channel 2\n" in out
    assert ('        rig config: [digitizer] dialect = "lecroy"; [digitizer.channels] doppler = "C1", '
            'response = "C2"\n') in out


def test_a_shot_whose_digitizer_speaks_another_dialect_names_the_dialect_to_set(tmp_path: Path, capsys) -> None:
    # issue 18: `probe` named the dialect to set, `shot` gave no fix. The rig config says generic,
    # the (simulated) instrument is a Keysight scope: refused before anything moves, with the fix.
    from hopkinson.rig.sim_session import sim_session
    from tests.rig.conftest import fast_sim_config, rig_toml, short_timeouts_config

    sim = dataclasses.replace(fast_sim_config(), servers=ServerParams(digitizer_dialect="keysight"))
    with sim_session(short_timeouts_config(), sim) as session:
        toml = rig_toml(session, tmp_path / "rig.toml")
        text = toml.read_text(encoding="utf-8").replace("timeout_s = 5.0", "timeout_s = 0.5", 1)
        toml.write_text(text, encoding="utf-8")
        assert main(["shot", "--config", str(toml), "--yes", "--out", str(tmp_path / "shots")]) == 2
        assert session.world.shots_fired == 0 and session.world.coils()["fill"] is False
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "could not be reached before the shot" in err and "nothing was moved" in err
    assert 'set [digitizer] dialect = "keysight" in rig.toml (it is "generic")' in err
