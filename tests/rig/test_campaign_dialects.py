"""A campaign of shots on each digitizer dialect: the simulated rig with its digitizer simulator
speaking generic SCPI, Keysight, Tektronix or LeCroy, the rig configured by role in that
dialect's channel names, the campaign runner's public API (rig.campaign), every shot fired,
triggered on the simulated world's signals, read back and stored with the dialect's codes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hopkinson.drivers.sim.scpi_digitizer import SimDigitizerServer
from hopkinson.drivers.sim.simulated_rig import SimulatedRig
from hopkinson.rig.campaign import CampaignRunner
from hopkinson.rig.events import EventBus
from hopkinson.rig.instruments import open_instruments, sim_rig_config
from hopkinson.rig.journal import Journal
from hopkinson.rig.plan import load_plan
from hopkinson.rig.run_folder import create_run_folder
from hopkinson.rig.shotfile import read_shot
from tests.drivers.digitizer_world import CHANNELS
from tests.rig.conftest import fast_sim_config, quick_analysis, short_timeouts_config

PLAN = """
name = "dialects"
operator = "tester"
authorise_firing = true
[accelerometer]
model = "SIM-ACC"
serial = "T1"
[defaults]
projectile = 3
[[shots]]
pressure_bar = 1.5
repeats = 2
"""
IDENTITY = {"generic": "Hopkinson-Sim", "keysight": "KEYSIGHT", "tektronix": "TEKTRONIX", "lecroy": "LECROY"}
FORMAT = {"generic": "uint16", "keysight": "int16", "tektronix": "float32", "lecroy": "int8"}


@pytest.mark.parametrize("dialect", tuple(CHANNELS))
def test_a_campaign_runs_on_each_digitizer_dialect(tmp_path: Path, dialect: str) -> None:
    sim = SimulatedRig(fast_sim_config())
    sim.digitizer = SimDigitizerServer(sim.world.capture, sim.faults, host=sim.config.servers.host, dialect=dialect)
    sim.start()
    try:
        config = sim_rig_config(short_timeouts_config(), sim)
        names = CHANNELS[dialect]
        digitizer = dataclasses.replace(
            config.digitizer, dialect=dialect, channels={"doppler": names[0], "response": names[1]},
            ranges_v={"doppler": 1.0, "response": 10.0}, trigger_source="response", record_length=40_000,
            sample_format=FORMAT[dialect], byte_order="big" if dialect == "tektronix" else "little")
        config = dataclasses.replace(config, digitizer=digitizer)
        plan_path = tmp_path / "plan.toml"
        plan_path.write_text(PLAN, encoding="utf-8")
        run = create_run_folder(plan_path, tmp_path / "runs", "run-1")
        truth = {}
        sim.world.launch_listeners.append(lambda t: truth.setdefault(t["shot_number"], t))
        with open_instruments(config, lambda: sim.world.last_shot_truth) as instruments:
            outcome = CampaignRunner(run, load_plan(plan_path), instruments, config, EventBus(),
                                     analyse=quick_analysis).run()
        channels_on = sim.digitizer.channels_on  # a scope starts with channel 1 alone on
    finally:
        sim.stop()
    assert outcome.exit_code == 0 and outcome.complete, outcome.message
    assert channels_on[1] and channels_on[2]  # ARM turned on both recorded channels
    assert sim.world.shots_fired == 2
    with Journal.open(run) as journal:
        assert [(s.state.value, s.fire_count) for s in journal.statuses()] == [("ANALYSED", 1)] * 2
    for sid in ("s001-r1", "s001-r2"):
        shot = read_shot(run.shot_path(sid))
        assert shot.meta.instruments["digitizer"].startswith(IDENTITY[dialect])
        response = shot.raw.channels["response"]
        assert response.codes.dtype == np.dtype(FORMAT[dialect]) and response.codes.size == 40_000
        assert shot.raw.trigger_index == 4_000  # 10 % pre-trigger, in every dialect's own units
        volts = shot.raw.volts("response")
        half_code = 0.5 * abs(response.scale_v) if response.codes.dtype.kind != "f" else 0.0
        assert volts[3_999] < 0.2 + half_code and volts[4_000] >= 0.2 - half_code  # on the trigger's crossing
        hole = dialect == "keysight"  # its lowest code is a hole: it clips one code above
        assert response.code_range == ((-10.0, 10.0) if dialect == "tektronix" else
                                       tuple(float(x) for x in (np.iinfo(response.codes.dtype).min + hole,
                                                                np.iinfo(response.codes.dtype).max)))
        peak_v = truth[1]["amplifier_gain"] * truth[1]["sensitivity_v_per_m_s2"] * truth[1]["peak_acceleration_m_s2"]
        assert 0.9 * peak_v < volts.max() < 2.0 * peak_v


@pytest.mark.parametrize("wrong", [{"trigger_level_v": 9.5}, {"trigger_slope": "NEG", "trigger_level_v": -2.0},
                                   {"trigger_source": "CH3"}])
def test_a_shot_with_a_wrong_trigger_fires_but_captures_nothing(make_rig, wrong: dict) -> None:
    """No fault injected: the simulated digitizer looks for the configured crossing in the
    world's signals and finds none, so the sequencer's no-trigger path ends the shot safe."""
    base = short_timeouts_config(capture_s=0.5)
    rig = make_rig(config=dataclasses.replace(base, digitizer=dataclasses.replace(base.digitizer, **wrong)))
    outcome = rig.run()
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == "CAPTURE" and outcome.fired
    assert "trigger" in outcome.error
    assert rig.world.shots_fired == 1 and rig.world.last_shot_truth["capture"] == {"triggered": False}
    rig.assert_safe()
