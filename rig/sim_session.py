"""An in-process simulated rig for `hopkinson shot --sim` (and tests): start it on free ports
with the asked-for faults, point a RigConfig at it, and at the end write the simulator's final
state as JSON (`--sim-state-file`).

    with sim_session(base_config, sim_config, faults=["door-open"], state_file=path) as session:
        with open_instruments(session.config, session.simulated_truth) as instruments:
            ...

The state file is written (atomically) when the `with` block ends, whatever way it ends
(after the sequencer has run SAFE), then the simulator is stopped. It holds the valves' real
positions (fire_valve_open, fill_valve_open, vent_valve_open: a stuck fill valve is open),
their commands (*_commanded), reservoir_pressure_bar, the watchdog and more (see
`world_state`).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hopkinson.drivers.sim.faults import FAULTS
from hopkinson.drivers.sim.simulated_rig import (
    SimConfig,
    SimulatedRig,
    write_state_file,
)
from hopkinson.drivers.sim.world import World
from hopkinson.rig.config import RigConfig
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.instruments import sim_rig_config


@dataclass
class SimSession:
    """A running simulated rig and the RigConfig that reaches it."""

    rig: SimulatedRig
    config: RigConfig

    @property
    def world(self) -> World:
        return self.rig.world

    def simulated_truth(self) -> dict[str, Any] | None:
        """The truth of the last shot fired (a copy), for the shot file."""
        truth = self.rig.world.last_shot_truth
        return copy.deepcopy(truth) if truth is not None else None

    def state(self) -> dict[str, Any]:
        return self.rig.state()


def check_fault_names(names: Iterable[str]) -> list[str]:
    """The names, or ConfigError naming the unknown one and listing the known ones."""
    names = list(names)
    for name in names:
        if name not in FAULTS:
            raise ConfigError(f"--sim-fault: unknown simulator fault {name!r}; known: {', '.join(FAULTS)}")
    return names


@contextlib.contextmanager
def sim_session(base: RigConfig, sim_config: SimConfig, faults: Iterable[str] = (),
                state_file: Path | None = None) -> Iterator[SimSession]:
    """Run a simulated rig on free loopback ports and ptys (no symlinks, so it never collides
    with a `hopkinson sim` process), with `faults` injected; module docstring."""
    names = check_fault_names(faults)
    if state_file is not None and not Path(state_file).parent.is_dir():
        raise ConfigError(f"--sim-state-file: folder {Path(state_file).parent} does not exist")
    servers = dataclasses.replace(sim_config.servers, modbus_port=0, digitizer_port=0)
    rig = SimulatedRig(dataclasses.replace(sim_config, servers=servers), names)
    rig.start()
    try:
        session = SimSession(rig, sim_rig_config(base, rig))
        try:
            yield session
        finally:
            if state_file is not None:
                write_state_file(state_file, session.state())
    finally:
        rig.stop()
