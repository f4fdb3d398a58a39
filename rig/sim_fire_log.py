"""Simulation only: the fire log, an independent witness that no shot was fired twice across
kills and resumes. `attach_fire_log` makes the simulated world append one JSON line per
projectile launch (fsynced), tagged with the campaign shot being fired (the campaign runner,
rig/campaign.py, tags it through its `on_shot_start`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.fileio import append_json_line
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.events import utc_now_iso
from hopkinson.rig.plan import PlannedShot

if TYPE_CHECKING:
    from hopkinson.drivers.sim.world import World


class FireLog:
    """Append-only JSON lines, one per simulated launch, each fsynced before the call returns."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise ConfigError(f"--sim-fire-log: folder {self.path.parent} does not exist")
        self.shot_id: str | None = None  # the campaign shot being fired, set by the runner

    def append(self, entry: dict[str, Any]) -> None:
        append_json_line(self.path, {"shot_id": self.shot_id, "pid": os.getpid(), "utc": utc_now_iso(), **entry})

    def set_shot(self, shot: PlannedShot | None) -> None:
        self.shot_id = shot.id if shot is not None else None


def attach_fire_log(world: World, log: FireLog) -> None:
    """Make the simulated `world` log every launch to `log` (test witness; simulation only).

    The line is written by the world's launch listener, in the simulator's server thread
    before the Modbus reply goes back, so the sequencer cannot have seen the shot fired
    without the line.
    """
    world.launch_listeners.append(lambda truth: log.append(
        {k: truth.get(k) for k in ("shot_number", "pressure_bar", "fired_at_sim_s")}))


def read_fire_log(path: str | Path) -> list[dict[str, Any]]:
    """The entries of a fire log (a missing file: none)."""
    path = Path(path)
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
