"""config/sim.toml as written: its [servers] (drivers/sim/simulated_rig.py), [world]
(drivers/sim/world_params.py) and the simulated controller's [register_map] (the driver's
tables, drivers/registers.py). Imported only by the commands that read a sim.toml."""

from __future__ import annotations

from dataclasses import dataclass, field

from hopkinson.drivers.config_fields import SECTION
from hopkinson.drivers.registers import RegisterMap
from hopkinson.drivers.sim.simulated_rig import ServerParams
from hopkinson.drivers.sim.world_params import WorldParams


@dataclass(frozen=True)
class SimFile:
    """config/sim.toml: every table optional (the defaults follow the method paper)."""

    __pydantic_config__ = SECTION
    servers: ServerParams = field(default_factory=ServerParams)
    world: WorldParams = field(default_factory=WorldParams)
    register_map: RegisterMap = field(default_factory=RegisterMap)
