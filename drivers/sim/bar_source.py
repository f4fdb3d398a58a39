"""The simulated rig's pulses from the bar model (hopkinson.analysis.bar): each shot's object
acceleration is what the rig's physics predicts for the projectile and reservoir pressure
(launcher, impact, dispersion, separation), times the shot's scatter of the projectile's speed.
Selected by `[world.realism] pulse_source = "bar"` (drivers/sim/world.py); `bar_mount` there says
how the object sits on the bar's end: "bonded" (it follows the bar: a bipolar pulse, as in PTB's
record) or "separating" (the paper's raster base, which flies off: a unipolar pulse)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from hopkinson.analysis.bar import PAPER_RIG, BarRig, predict_shot
from hopkinson.drivers.sim.real_records import PulseShape, tabulated_pulse


@dataclass(frozen=True)
class BarPulseSource:
    """projectile + pressure → the bar model's pulse (PulseSource). The launcher is the bar
    model's own (the [world.launcher] closed form does not apply)."""

    rig: BarRig = field(default_factory=lambda: PAPER_RIG)
    name: str = "bar"

    @classmethod
    def mounted(cls, mount: str) -> BarPulseSource:
        """The paper's rig with the object mounted `mount` (analysis.bar.geometry.MOUNTS)."""
        return cls(replace(PAPER_RIG, mount=mount))

    def pulse(self, projectile: int, pressure_bar: float, speed_factor: float = 1.0) -> PulseShape:
        speed = self.rig.launcher.speed_m_s(self.rig.projectile(projectile), pressure_bar) * speed_factor
        shot = predict_shot(self.rig, projectile, speed_m_s=speed)
        a = shot.acceleration_m_s2
        moving = np.flatnonzero(a != 0.0)
        end = int(moving[-1]) + 2 if moving.size else 2  # the pulse and a sample of flight
        return tabulated_pulse(shot.time_s[:end], a[:end], shot.speed_m_s, shape="bar_model")
