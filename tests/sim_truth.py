"""Independent truths of a simulated shot, for tests: what the simulated sensor's own continuous
model (drivers/sim/world.accelerometer_truth, recorded with every shot) says, not what the
analysis found."""

from __future__ import annotations

import numpy as np

from hopkinson.analysis.response import band_edges
from hopkinson.drivers.sim.shot_truth import accelerometer_truth


def true_fbsd_hz(truth: dict, level: float) -> float:
    """The band edge (±level) of the simulated accelerometer and its amplifier (continuous)."""
    acc = accelerometer_truth(truth)

    def gain(f: np.ndarray) -> np.ndarray:
        h = acc.frequency_response(np.atleast_1d(f))
        return np.abs(h) / abs(acc.frequency_response(np.array([1e-3]))[0])

    return band_edges(gain, 200e3, (level,), np.array([m.natural_frequency_hz for m in acc.modes]))[
        f"{round(level * 100)}"].frequency_hz


def shot_truth_figures(truth: dict) -> dict[str, float]:
    """The figures an analysis reports, as the simulated sensor has them (the truth's "sensor"
    block, drivers/sim/sensor_truth.py): its DC gain, the mean of both directions (compression 1:
    the model is normalised), the mounted main mode's natural frequency and damping ratio, its
    FBSD ±5 % and ±10 % (checked against this module's own band_edges), and ε."""
    sensor = truth["sensor"]
    fbsd = {level: true_fbsd_hz(truth, level / 100) for level in (5, 10)}
    for level, edge in fbsd.items():  # two independent computations of the same truth
        assert abs(edge / sensor["fbsd_hz"][str(level)] - 1.0) < 1e-6, (level, edge, sensor["fbsd_hz"])
    return {"sensitivity": sensor["dc_gain"], "natural_frequency_hz": sensor["natural_frequency_hz"],
            "damping_ratio": sensor["damping_ratio"], "fbsd_5": fbsd[5], "fbsd_10": fbsd[10],
            "asymmetry": sensor["asymmetry_epsilon"]}
