"""Issue 40 item 2 with the power issue 45 item 3 asks for: each 95 % interval on the shipped
realistic simulator holds its truth in at least 90 % of the shots, tested so that a 90 % coverage
fails.

Who runs it: `make studies` (CI's second stage, `.ci/run`), not `make test`: SHOTS shots cost
about 5 minutes of CPU, more than the suite's whole budget.

Why 200 shots: a well-sized 95 % interval misses its truth on 1 shot in 20. The suite's 50-shot
study (tests/analysis/test_coverage_realistic.py) allows 1 miss, which rejects a 90 % coverage
with 97 % probability but passes a calibrated 95 % interval only with probability 0.28: it holds
intervals that are conservative, and cannot pass one that is right. f_n on projectile No. 3 is
right: over 40 shots at 3.5 bar (shot numbers 101-140), 37 held, the errors' mean +0.0001 % and
their spread 1.05 standard uncertainties. Telling 95 % from 90 % needs some 200 trials.

The plan is tests.realistic_study's (fixed before any result was seen); its first 50 shots are the
suite's. Each figure (the five of issue 40 item 2, and ε, the tension/compression asymmetry of the
bonded mount: tests/analysis/test_bonded_bar_shots.py's five shots cannot test its coverage) passes with at most `max_misses(claims)` misses: the largest count whose
probability at a 90 % coverage is ≤ 5 % (scipy.stats.binom). For 200 claims that is 12 misses:
P(pass | 90 %) = 0.032, P(pass | 95 %) = 0.80, P(pass | 97 %) = 0.99.
"""

from __future__ import annotations

import os

import pytest

from tests.realistic_study import coverage, run_study
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
