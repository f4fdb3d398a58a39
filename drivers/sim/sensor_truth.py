"""What the simulated sensor truly is, in the terms the analysis reports: recorded with
every simulated shot as the truth's "sensor" block, so a test, a study or the demo compares each
reported figure with the same definition.

- **sensitivity**: the mean of the DC gains in both directions, relative to the bridge's nominal
  sensitivity (1 = on nominal), as the analysis reports it (analysis.input_terms): compression
  (the bar's pulse is compression first: the main direction) 1, tension 1 − the mount's
  asymmetry; beside them ε = tension ÷ compression − 1, the figure the analysis fits;
- **the mounted main mode** (natural frequency and damping: the mount stiffens the
  sine-calibrated resonance) and the FBSD ±5 % and ±10 % edges of the sensor and its amplifier
  (the first frequency where |H(f)/H(0)| leaves 1 ± level; computed here from the continuous
  model, independently of the analysis);
- the transverse sensitivity and the amplitude non-linearity the simulator applies.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import brentq

from hopkinson.drivers.sim.accelerometer import AccelerometerTruth

FBSD_LEVELS = (0.05, 0.10)
REPORTED = "the mean of both directions (compression and tension)"


def fbsd_hz(acc: AccelerometerTruth, level: float, f_max_hz: float = 500e3) -> float:
    """The first frequency where |H(f)/H(0)| of the continuous model leaves 1 ± level (f_max_hz
    when it never does below it)."""
    dc = abs(acc.frequency_response(np.array([1e-3]))[0])

    def excess(f: float) -> float:
        return abs(abs(acc.frequency_response(np.array([f]))[0]) / dc - 1.0) - level

    grid = np.linspace(1.0, f_max_hz, 20_001)
    g = np.abs(np.abs(acc.frequency_response(grid)) / dc - 1.0) - level
    outside = np.flatnonzero(g > 0)
    if outside.size == 0:
        return float(f_max_hz)
    i = int(outside[0])
    return float(brentq(excess, grid[i - 1], grid[i], xtol=1e-6)) if i > 0 else float(grid[0])


def sensor_truth(acc: AccelerometerTruth, asymmetry_rel: float, transverse_sensitivity_rel: float,
                 nonlinearity_per_m_s2: float) -> dict[str, Any]:
    """The truth's "sensor" block (module docstring); `asymmetry_rel` the mount's gain lost in
    tension (0 without a mount), `transverse_sensitivity_rel` 0 without a transverse drive."""
    main = acc.modes[0]
    return {
        "sensitivity_reported": REPORTED,
        "dc_gain": 1.0 - 0.5 * asymmetry_rel,  # the mean of both directions (normalised to the nominal)
        "dc_gain_compression": 1.0,
        "dc_gain_tension": 1.0 - asymmetry_rel,
        "asymmetry_epsilon": -asymmetry_rel,  # tension ÷ compression − 1
        "natural_frequency_hz": main.natural_frequency_hz,
        "damping_ratio": main.damping_ratio,
        "fbsd_hz": {f"{round(100 * level)}": fbsd_hz(acc, level) for level in FBSD_LEVELS},
        "transverse_sensitivity_rel": transverse_sensitivity_rel,
        "nonlinearity_per_m_s2": nonlinearity_per_m_s2,
    }
