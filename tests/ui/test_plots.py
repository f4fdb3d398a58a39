"""The results strip's numbers from an analysis results dict (ui.plots.summary_of)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hopkinson.analysis.excitation import excitation_summary
from hopkinson.drivers.sim.shock import half_sine_m_s2


def test_pulse_figures_come_from_the_excitation_without_a_reduction():
    """A record analysed without an interferometer reduction: peak and 10 % width of the
    reference pulse, checked against the half-sine's closed form."""
    from hopkinson.ui.plots import summary_of

    dt, width_s, peak = 1e-7, 50e-6, 2.0e5
    t = np.arange(3000) * dt
    summary = summary_of({"excitation": excitation_summary(half_sine_m_s2(t, width_s, peak, 50e-6), dt).to_dict()})
    assert summary["pulse_width_s"] == pytest.approx(width_s * (1 - 2 * math.asin(0.1) / math.pi), rel=1e-3)
    assert summary["peak_acceleration_m_s2"] == pytest.approx(peak, rel=1e-3)
