"""Issue 40 item 2 with the power issue 45 item 3 asks for: each 95 % interval on the shipped
realistic simulator holds its truth in at least 90 % of the shots, tested so that a 90 % coverage
fails.

Who runs it: `make studies` (CI's second stage, `.ci/run`), not `make test`: SHOTS shots cost
about 5 minutes of CPU, more than the suite's whole budget.

Why 200 shots: a well-sized 95 % interval misses its truth on 1 shot in 20. The 50-shot
study (tests/analysis/test_coverage_realistic.py) allows 1 miss, which rejects a 90 % coverage
with 97 % probability but passes a calibrated 95 % interval only with probability 0.28: it holds
intervals that are conservative, and cannot pass one that is right. f_n on projectile No. 3 is
right: over 40 shots at 3.5 bar (shot numbers 101-140), 37 held, the errors' mean +0.0001 % and
their spread 1.05 standard uncertainties. Telling 95 % from 90 % needs some 200 trials.

The plan is tests.realistic_study's (fixed before any result was seen); its first 50 shots are
test_coverage_realistic's, which `make studies` runs before this module in the same process: they
are computed once (tests/realistic_study.py keeps each shot's outcome). Each figure (the five of
issue 40 item 2, and ε, the tension/compression asymmetry of the bonded mount: tests/analysis/test_bonded_bar_shots.py's five shots cannot test its coverage) passes with at most `max_misses(claims)` misses: the largest count whose
probability at a 90 % coverage is ≤ 5 % (scipy.stats.binom). For 200 claims that is 12 misses:
P(pass | 90 %) = 0.032, P(pass | 95 %) = 0.80, P(pass | 97 %) = 0.99.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from tests.realistic_study import (
    coverage,
    modes_the_truth_lacks,
    pairwise_e_n,
    run_study,
    too_wide_or_far,
)
from tests.studies.binomial import max_misses, pass_probability

pytestmark = pytest.mark.study

SHOTS = 200
DRAWS = 100  # as the suite's study and a rig's shot
FIGURES = ("sensitivity", "natural_frequency_hz", "damping_ratio", "fbsd_5", "fbsd_10", "asymmetry")


@pytest.fixture(scope="module")
def study():
    return run_study("shipped", SHOTS, draws=DRAWS, workers=os.cpu_count() or 1)


def test_the_threshold_has_the_stated_power() -> None:
    assert max_misses(SHOTS) == 12
    assert pass_probability(SHOTS, 0.90) <= 0.05  # a 90 % coverage fails with probability ≥ 95 %
    assert pass_probability(SHOTS, 0.95) >= 0.79  # a calibrated 95 % interval passes with 0.80
    assert pass_probability(SHOTS, 0.90, misses=13) > 0.05  # and no larger count would do


@pytest.mark.parametrize("name", FIGURES)
def test_each_interval_holds_the_truth_in_at_least_90_percent_of_200_shots(study, name: str) -> None:
    row = coverage(study)[name]
    assert row.claims >= 0.9 * SHOTS, row  # the figure is determined on (nearly) every shot
    assert row.claims - row.holds <= max_misses(row.claims), row


def test_the_intervals_are_not_needlessly_wide_over_200_shots(study) -> None:
    """test_coverage_realistic's bound on all 200 shots: the median U at most 7.5 × the median
    |error| (the issue asks 4 ×, not yet met), and no miss farther than 2 U from its truth.
    Measured (2026-11-29): 6.38, 6.60, 6.09, 5.46 and 5.42 (DC gain, f_n, ζ, FBSD ±5 %, ±10 %); 6.52,
    6.61, 6.30, 5.46 and 5.43 since the band is judged without the onset's glitches (decision 0027)."""
    assert too_wide_or_far(study, 7.5) == []


@pytest.mark.parametrize("name", ["sensitivity", "fbsd_5", "fbsd_10"])
def test_one_unchanged_sensor_agrees_with_itself_over_200_shots(study, name: str) -> None:
    """Issue 40 item 5 on all 200 shots (19 900 pairs): E_n > 1 on at most 4.6 % of pairs, what
    unbiased normal estimates with exact 95 % U give. Measured (2026-11-29): 0.09 %, 0.13 % and
    0.11 % (DC gain, FBSD ±5 %, ±10 %); 0.09 %, 0.01 % and 0.01 % since decision 0027."""
    e_n = pairwise_e_n(study, name)
    assert e_n.size >= math.comb(math.ceil(0.9 * SHOTS), 2), name  # claimed on ≥ 90 % of the shots
    assert np.mean(e_n > 1.0) <= 0.046, np.sort(e_n)[-5:]


def test_no_mode_is_claimed_that_the_truth_lacks_over_200_shots(study) -> None:
    """Issue 40 item 3 on all 200 shots: every claimed mode is the sensor's (29.7 kHz, f_n within
    0.5 %). test_coverage_realistic holds it on the first 50. Until decision 0027 (the band judged on
    the reference without its fitted onset disturbances) shot 60 claimed a second mode at 171.3 kHz,
    ζ 0.0024, in a band its reference's glitches had lifted to 204 kHz
    (tests/analysis/test_onset_glitches.py holds that shot in `make test`)."""
    assert modes_the_truth_lacks(study) == []

