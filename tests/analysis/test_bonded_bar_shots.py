"""Shots of the simulator through the bar model with the sensor bonded to the bar's end (PTB's
mounting: a bipolar pulse with no net velocity change, its first spectral null near 20 kHz for
projectile No. 3), read by a quadrature interferometer (the velocity comes back through zero).

The truth is the simulated sensor (a 29.7 kHz mode, ζ 0.05, as mounted; its FBSD ±5 % in closed
form, 6.50 kHz). The shots carry every realism effect: the mount's 2 % gain loss in tension (a
lobe-dependent gain: half a bipolar pulse's energy goes through it, and its error lives where
such a pulse is weak, at the band's bottom), the bar's motion after the pulse, the second drive
path, the interferometer's f⁴ noise. Each shot's FBSD ±5 % must lie within 12 % of the truth, and
the lobe-gain asymmetry must be reported, not absorbed by the model: until issue 40 as model error;
since, measured as its own figure ε (analysis.input_terms), inside its interval, and the FBSD
within 1 % of the truth (measured: within 0.4 %).

Until stop 31 this failed (one shot at 63 Hz, one at +43 %): the reference's noise was measured
on 64 samples of flight and bar motion between the pulse and where the motion's coherence
showed (the sensor's ringing hid it), which put the noise in the band ~10⁴ times too high; the
model error then went unseen and spare real poles followed it. Measured over 24 shots after
the fix: −5.5 … +9 %, the model error detected on every one.

ε's containment is counted, not required on every shot (issue 45 item 3: it failed once on
shot 2, ε [−0.0541, −0.0206] against −0.020): at most MAX_EPSILON_MISSES of the 5 shots may miss.
Power (scipy.stats.binom): P(pass | 95 %) = 0.977; P(pass | 90 %) = 0.919: five shots (~2.5 s
each) cannot reject 90 %; they reject only a coverage below 34 % with 95 % probability. ε's
coverage with power is held on the shipped simulator's bonded mount over 200 shots
(tests/studies/test_realistic_coverage_powered.py, `make studies`: P(pass | 90 %) = 0.032).
"""

from __future__ import annotations

import dataclasses

from scipy.stats import binom

from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.shot_analysis import analyse_raw_shot
from hopkinson.drivers.sim.world import CaptureSettings, simulate_shot
from hopkinson.rig.config import load_sim_config
from tests.rig.conftest import REPO
from tests.sim_truth import true_fbsd_hz

SHOTS = ((1, 1.0), (2, 2.0), (3, 3.0), (4, 2.0), (5, 2.0))  # (shot number: its seed, pressure in bar)
MAX_EPSILON_MISSES = 1


def test_the_threshold_has_the_stated_power() -> None:
    assert binom.cdf(MAX_EPSILON_MISSES, len(SHOTS), 0.05) >= 0.95  # 0.977
    assert binom.cdf(MAX_EPSILON_MISSES, len(SHOTS), 0.66) <= 0.05  # rejects a coverage of 34 %


def test_bonded_bar_shots_give_the_true_fbsd_and_measure_the_lobe_gain_asymmetry() -> None:
    world = load_sim_config(REPO / "config" / "sim.toml").world
    world = dataclasses.replace(world, signals=dataclasses.replace(world.signals, quadrature=True),
                                realism=dataclasses.replace(world.realism, pulse_source="bar", bar_mount="bonded"))
    found, epsilon_misses = [], []
    for number, pressure in SHOTS:
        channels, truth = simulate_shot(world, pressure, 3, CaptureSettings(100e6, 200_000, 20_000),
                                        shot_number=number)
        result = analyse_raw_shot(channels[1], channels[2], 1e-8, AnalysisOptions(
            amp_gain=truth["amplifier_gain"], sensitivity_v_per_m_s2=truth["sensitivity_v_per_m_s2"],
            max_order=4, draws=50), quadrature_v=channels[3]).to_dict()
        found.append((result["fbsd_hz"]["5"], true_fbsd_hz(truth, 0.05)))
        epsilon = result["uncertainty"]["input_terms"]["asymmetry"]  # tension ÷ compression − 1
        if not epsilon["interval"][0] <= truth["sensor"]["asymmetry_epsilon"] <= epsilon["interval"][1]:
            epsilon_misses.append((number, epsilon["interval"], truth["sensor"]["asymmetry_epsilon"]))
    assert len(epsilon_misses) <= MAX_EPSILON_MISSES, epsilon_misses
    assert all(abs(got / true - 1) <= 0.01 for got, true in found), found
