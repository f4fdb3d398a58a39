"""Independent truths of a simulated shot, for tests: what the simulated sensor's own continuous
model (drivers/sim/world.accelerometer_truth, recorded with every shot) says, not what the
analysis found."""

from __future__ import annotations

import numpy as np
from hopkinson.analysis.response import band_edges
from hopkinson.drivers.sim.world import accelerometer_truth


def true_fbsd_hz(truth: dict, level: float) -> float:
    """The band edge (±level) of the simulated accelerometer and its amplifier (continuous)."""
    acc = accelerometer_truth(truth)

    def gain(f: np.ndarray) -> np.ndarray:
        h = acc.frequency_response(np.atleast_1d(f))
        return np.abs(h) / abs(acc.frequency_response(np.array([1e-3]))[0])

    return band_edges(gain, 200e3, (level,), np.array([m.natural_frequency_hz for m in acc.modes]))[
        f"{round(level * 100)}"].frequency_hz


def shot_truth_figures(truth: dict) -> dict[str, float]:
    """The figures an analysis reports, as the simulated sensor has them: its DC gain in the main
    pulse's direction (compression: 1, the model is normalised), the mounted main mode's natural
    frequency and damping ratio, and its FBSD ±5 % and ±10 %."""
    mode = accelerometer_truth(truth).modes[0]
    return {"sensitivity": 1.0, "natural_frequency_hz": mode.natural_frequency_hz,
            "damping_ratio": mode.damping_ratio, "fbsd_5": true_fbsd_hz(truth, 0.05),
            "fbsd_10": true_fbsd_hz(truth, 0.10)}
