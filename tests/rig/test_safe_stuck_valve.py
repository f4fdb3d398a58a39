"""SAFE that cannot confirm names a stuck valve, also when the controller's link fails after
the valve was seen stuck (the last round ends in an instrument error, not a read-back)."""

from __future__ import annotations

from hopkinson.rig.events import Reading, RigEvent
from tests.rig.conftest import short_timeouts_config
from tests.rig.test_sequencer import _leave_the_rig_charged


def test_safe_names_the_stuck_valve_it_read_before_the_link_failed(make_rig) -> None:
    rig = make_rig(config=short_timeouts_config(safe_s=1.0))
    _leave_the_rig_charged(rig, stuck_fill_valve=True)

    def lose_the_link(event: RigEvent) -> None:  # after SAFE's first full read-back
        if isinstance(event, Reading) and not rig.faults.active("modbus-disconnect"):
            rig.faults.inject("modbus-disconnect")

    rig.bus.subscribe(lose_the_link)
    confirmed, problem = rig.sequencer.make_safe()
    assert confirmed is False
    assert problem.startswith(rig.instruments.valves.name), problem  # the error of the last round ...
    assert problem.endswith("; last read back: fill valve commanded shut but open"), problem  # ... and the valve
    rig.assert_safe(vented=False, stuck=("fill",), read_back=False)  # SAFE's commands came before the link went
    assert rig.world.valve_positions()["fill"] is True  # the valve itself is stuck open
