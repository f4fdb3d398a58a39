"""Shots of the simulator through the bar model with the sensor bonded to the bar's end (PTB's
mounting: a bipolar pulse with no net velocity change, its first spectral null near 20 kHz for
projectile No. 3), read by a quadrature interferometer (the velocity comes back through zero).

The truth is the simulated sensor (a 29.7 kHz mode, ζ 0.05, as mounted; its FBSD ±5 % in closed
form). What the default analysis must do, and does not yet (issue 19 item 2's blocker for making
this the shipped simulator; issue 17's method on a record like PTB's): give each shot's FBSD
±5 % within 25 % of the truth. Measured at this commit: three of five within 8 %, one at 9.3 kHz
(+43 %), and one at 63 Hz: an order-3 fit whose gain bends by 5 % below 0.5 kHz, at the bottom
of the supported band, where a bipolar pulse (nothing at DC) is weak. What drives
it, measured on those two shots one effect at a time: the mount's 2 % gain loss in tension
(without it: 6.68 and 6.82 kHz; order 2 imposed on the shots as they are: 6.76 and 6.89 kHz).
A bipolar pulse puts half its energy through that non-linearity, and the order test accepts
extra orders that bend the model where the pulse has no energy.
"""

from __future__ import annotations

import dataclasses

import pytest
from hopkinson.analysis.params import AnalysisParams
from hopkinson.analysis.shot_analysis import analyse_raw_shot
from hopkinson.drivers.sim.world import CaptureSettings, simulate_shot
from hopkinson.rig.config import load_sim_config

from tests.rig.conftest import REPO
from tests.sim_truth import true_fbsd_hz

SHOTS = ((1, 1.0), (2, 2.0), (3, 3.0), (4, 2.0), (5, 2.0))  # (shot number: its seed, pressure in bar)


@pytest.mark.xfail(strict=True, raises=AssertionError, reason="issue 19 item 2 / issue 17: on bonded bar shots one FBSD comes out "
                                       "at 63 Hz (an order-3 fit bent where a pulse with nothing at DC is weak) "
                                       "and one 43 % high; the shipped simulator keeps the ideal pulse until this holds")
def test_bonded_bar_shots_give_the_true_fbsd_within_25_percent() -> None:
    world = load_sim_config(REPO / "config" / "sim.toml").world
    world = dataclasses.replace(world, signals=dataclasses.replace(world.signals, quadrature=True),
                                realism=dataclasses.replace(world.realism, pulse_source="bar", bar_mount="bonded"))
    found = []
    for number, pressure in SHOTS:
        channels, truth = simulate_shot(world, pressure, 3, CaptureSettings(100e6, 200_000, 20_000),
                                        shot_number=number)
        result = analyse_raw_shot(channels[1], channels[2], 1e-8, AnalysisParams(
            amp_gain=truth["amplifier_gain"], sensitivity_v_per_m_s2=truth["sensitivity_v_per_m_s2"],
            max_order=4, draws=50), quadrature_v=channels[3]).to_dict()
        found.append((result["fbsd_hz"]["5"], true_fbsd_hz(truth, 0.05)))
    assert all(abs(got / true - 1) <= 0.25 for got, true in found), found
