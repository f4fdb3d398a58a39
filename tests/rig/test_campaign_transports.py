"""A campaign of shots with the valve controller on Modbus RTU (a simulated RS-485 line at its
baud rate, a register map with 32-bit and float values after gaps) under the rig's own control
(lock, heartbeat session, controller-timed fire pulses): the same path as Modbus TCP."""

from __future__ import annotations

from pathlib import Path

import pytest

from hopkinson.drivers.sim.controller_map import Point, default_map
from hopkinson.drivers.sim.simulated_rig import ServerParams, SimConfig, SimulatedRig
from hopkinson.drivers.sim.world import WorldParams
from hopkinson.rig.campaign import CampaignRunner
from hopkinson.rig.control import controlled_rig
from hopkinson.rig.events import EventBus
from hopkinson.rig.instruments import sim_rig_config
from hopkinson.rig.journal import Journal
from hopkinson.rig.plan import load_plan
from hopkinson.rig.run_folder import create_run_folder
from tests.rig.conftest import quick_analysis, short_timeouts_config
from tests.rig.test_campaign_dialects import PLAN  # two shots at 1.5 bar, firing authorised


@pytest.mark.parametrize("transport", ["rtu", "tcp"])
def test_a_campaign_runs_with_the_controller_on_each_transport(tmp_path: Path, transport: str) -> None:
    layout = default_map()
    layout["input_registers"].update(reservoir_pressure=Point(10, "int32", "little", scale=1e-4),
                                     fixture_vacuum=Point(20, "float32"))
    sim_config = SimConfig(world=WorldParams(time_scale=100.0), register_map=layout,
                           servers=ServerParams(modbus_transport=transport, modbus_baudrate=115200,
                                                modbus_unit_id=5, modbus_slow_delay_s=0.8))
    with SimulatedRig(sim_config) as sim:
        config = sim_rig_config(short_timeouts_config(), sim)
        assert config.valve_controller.transport == transport and config.valve_controller.unit_id == 5
        plan_path = tmp_path / "plan.toml"
        plan_path.write_text(PLAN, encoding="utf-8")
        run = create_run_folder(plan_path, tmp_path / "runs", "run-1")
        with controlled_rig(config, command="test campaign", simulated_truth=lambda: sim.world.last_shot_truth) as c:
            assert sim.world.watchdog_state() == "armed"  # the heartbeat session is on
            outcome = CampaignRunner(run, load_plan(plan_path), c.instruments, config, EventBus(),
                                     analyse=quick_analysis).run()
        watchdog_after = sim.world.watchdog_state()
    assert outcome.exit_code == 0 and outcome.complete, outcome.message
    assert sim.world.shots_fired == 2 and sim.world.fire_pulses == 2  # each shot one controller-timed pulse
    assert sim.world.watchdog_trips == 0 and watchdog_after == "off"  # disarmed on the way out
    with Journal.open(run) as journal:
        assert [(s.state.value, s.fire_count) for s in journal.statuses()] == [("ANALYSED", 1)] * 2
