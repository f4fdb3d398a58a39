"""Issue 40 item 2: on the shipped realistic simulator (config/sim.toml as shipped: the bar model's
bonded pulse, every realistic effect on), each 95 % interval holds the simulated sensor's truth,
held statistically.

The study (tests/realistic_study.py, computed once for the module): SHOTS shots, projectiles 1, 2,
3 in turn at pressures drawn uniformly over 1–6 bar by a generator fixed before any result was
seen, each analysed as a rig's shot (DRAWS Monte Carlo draws; the reference chain left out: exact
in the simulator, a pure scale of the DC gain). The truth is the sensor's own (the shot's truth
"sensor" block).

Power (scipy.stats.binom): each figure passes with at most MAX_MISSES misses among the shots that
claim it. Were the true coverage 90 % (what the issue must reject), a figure claimed on all 50
shots would pass with probability P(X ≥ 49 | n = 50, p = 0.90) = 0.034 (≤ 5 %); at 98 % it passes
with 0.74, at 99 % with 0.91. f_n, whose interval is a calibrated 95 % one, is held at 2 misses
(F_N_MAX_MISSES: P(pass | 90 %) = 0.11); the power the issue asks for every figure is the 200-shot
study's (tests/studies/test_realistic_coverage_powered.py, `make studies`, CI). This module guards
against a collapse of any figure's coverage. Its tests of the study are marked `study`: `make
studies` runs them (CI, after `make test`) on the 200-shot study's first 50 shots, computed once
(tests/realistic_study.py keeps each shot's outcome per process); `make test` keeps the thresholds'
power and the one low shot below. docs/coverage_realistic.py prints the full study (more shots,
each effect alone, the demo over many seeds).
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from scipy.stats import binom

from tests.realistic_study import (
    coverage,
    modes_the_truth_lacks,
    pairwise_e_n,
    run_study,
    too_wide_or_far,
)

SHOTS = 50
MAX_MISSES = 1
DRAWS = 100


@pytest.fixture(scope="module")
def study():
    return run_study("shipped", SHOTS, draws=DRAWS, workers=os.cpu_count() or 1)


def test_the_test_rejects_a_coverage_of_90_percent() -> None:
    """The design's own power, as the module docstring states it."""
    assert binom.sf(SHOTS - MAX_MISSES - 1, SHOTS, 0.90) <= 0.05
    assert binom.sf(SHOTS - MAX_MISSES - 1, SHOTS, 0.98) >= 0.7


# f_n's interval is a calibrated 95 % one where the pulse excites the resonance most (projectile
# No. 3): over 40 shots at 3.5 bar (shot numbers 101-140) 37 held, the errors' mean +0.0001 % and
# their spread 1.05 standard uncertainties. A calibrated 95 % interval has at most 1 miss of 50 with
# probability 0.28 only, so f_n is held at F_N_MAX_MISSES = 2 here (P(pass | 90 %) = 0.11, P(pass |
# 95 %) = 0.54, P(pass | 98 %) = 0.92; measured: 2), and at the power the issue asks over 200 shots
# by tests/studies/test_realistic_coverage_powered.py (`make studies`: 196 of 200 held).
F_N_MAX_MISSES = 2


def test_f_ns_threshold_has_the_stated_power() -> None:
    assert binom.cdf(F_N_MAX_MISSES, SHOTS, 0.10) <= 0.12
    assert binom.cdf(F_N_MAX_MISSES, SHOTS, 0.02) >= 0.9


@pytest.mark.study
@pytest.mark.parametrize("name", ["sensitivity", "damping_ratio", "natural_frequency_hz", "fbsd_5", "fbsd_10"])
def test_each_interval_holds_the_truth_on_the_realistic_simulator(study, name: str) -> None:
    row = coverage(study)[name]
    assert row.claims >= 0.9 * SHOTS, row  # the figure is determined on (nearly) every shot
    assert row.claims - row.holds <= (F_N_MAX_MISSES if name == "natural_frequency_hz" else MAX_MISSES), row


@pytest.mark.study
def test_the_intervals_are_not_needlessly_wide(study) -> None:
    """The median U at most 7.5 × the median |error| (the issue asks 4 ×: not yet met; measured 5.2-6.7
    since the band is judged without the onset's glitches (decision 0027), 5.4-6.7 before, since a refitted variant's Type B shift is what the record's noise does not explain
    (systematics.beyond_noise), 6.2-7.4 before, when this asked 8 ×, since the interval's ends are
    the draws at ranks (M + 1)p (decision 0025), 5.8-6.5 before,
    since the order's row is weighed by its evidence, 5.2-8.3 before, when this asked 10 ×; the
    structure row is most of what remains: docs/systematic-effects.md), and the
    shots that miss do so by a little (within 2 U): no interval is a point beside a biased value."""
    assert too_wide_or_far(study, 7.5) == []


@pytest.mark.study
def test_no_mode_is_claimed_that_the_truth_lacks(study) -> None:
    """The simulated sensor has one mode (29.7 kHz, ζ 0.05): every claimed mode is it (issue 40
    item 3: shots claimed modes at 18.5, 20.2, 20.8, 33.65 and 55-66 kHz, ζ up to 0.75), f_n within
    0.5 % of it where the pulse excites it between its nulls (item 4)."""
    assert modes_the_truth_lacks(study) == []


@pytest.mark.study
def test_the_planner_and_the_analysis_agree_on_the_band(study) -> None:
    """Both use one rule (analysis.excitation.supported_band): the planner on the predicted pulse,
    the analysis on the measured one, whose noise, onset glitches and cut where the model stops
    explaining the response move its top. The analysis' top is at least half the planner's on every
    shot, and its median ratio to it within 30 %."""
    ratios = np.array([o.band_top_hz / o.planned_top_hz for o in study if o.band_top_hz])
    assert ratios.size >= 0.9 * SHOTS
    assert np.all(ratios >= 0.5), np.sort(ratios)[:5]
    assert 0.7 <= float(np.median(ratios)) <= 1.3, float(np.median(ratios))


@pytest.mark.study
def test_one_unchanged_sensor_agrees_with_itself(study) -> None:
    """Issue 40 item 5: the study's shots are one sensor at different levels and projectiles; the
    DC gain and the FBSD of every pair of them agree within their uncertainties. E_n = |x₁ − x₂| /
    √(U₁² + U₂²) exceeds 1 on 4.6 % of pairs for unbiased normal estimates with exact 95 % U (the
    difference beyond 2 of its standard deviations); more is a false drift between shots of one
    sensor. Measured: 1, 3 and 19 of 1 225 pairs (DC gain, FBSD ±5 %, ±10 %); 1, 1 and 1 since decision
    0026 (2026-11-29; over the 200-shot study's 19 900 pairs: 0.09-0.13 %)."""
    for name in ("sensitivity", "fbsd_5", "fbsd_10"):
        e_n = pairwise_e_n(study, name)
        assert e_n.size >= math.comb(math.ceil(0.9 * SHOTS), 2), name  # claimed on ≥ 90 % of the shots
        assert np.mean(e_n > 1.0) <= 0.046, (name, np.sort(e_n)[-5:])


def test_a_low_pulse_whose_resonance_lies_beyond_its_band_is_analysed() -> None:
    """Projectile No. 3 at 1.04 bar (docs/dcm_realistic.py's shot 24): the band stops at the
    pulse's first null (19.2 kHz), below the 29.7 kHz resonance, and no model with free zeros is a
    candidate there (each presses a pole onto the unit circle). The analysis refused the shot ("no
    stable model of order 1 … 12"); the all-pole model, whose damping beyond the band is floored,
    is used as where a free choice is unstable, with its model error measured and carried. The
    resonance is not claimed, and each figure lies within 2 U of its truth (one shot: its holding
    is the study's to count)."""
    from tests.realistic_study import run_shot, world_params

    outcome = run_shot(world_params("shipped"), 3, 1.0385214471004196, 24, draws=60, keep_results=True)
    assert outcome.error is None, outcome.error
    assert outcome.results["identification"]["order_evidence"]["structure"] == "all_pole"
    warnings = outcome.results["warnings"]
    assert any(w.startswith("model error:") for w in warnings), warnings
    assert outcome.modes_hz == [] and "natural_frequency_hz" in outcome.not_determined
    for name in ("sensitivity", "fbsd_5", "fbsd_10"):
        lo, hi = outcome.interval[name]
        assert lo <= outcome.value[name] <= hi
        assert abs(outcome.value[name] - outcome.truth[name]) <= hi - lo, (name, outcome.value[name], (lo, hi))
