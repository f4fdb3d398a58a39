"""Issue 40 item 2, third bullet: with each realistic effect alone (the transverse drive, the
mount's tension/compression asymmetry, the reference's onset glitches, the bar's ringing), each
95 % interval holds the simulated sensor's truth in at least 85 % of the shots that claim it,
tested so that a coverage of 85 % fails.

Who runs it: `make studies` (CI's second stage), not `make test`: four worlds of SHOTS shots cost
about 7 minutes of CPU.

The worlds are tests.realistic_study's (`_only`: one effect on; the bar's pulse, the mount's
stiffening and the reference chain's noise, low-pass and delay stay, as on every bar), the plan is
its fixed one (projectiles 1, 2, 3 in turn, 1–6 bar, drawn before any result was seen), each shot
analysed as a rig's shot with DRAWS Monte Carlo draws. Each figure passes with at most
`max_misses(claims, 0.85)` misses: the largest count a coverage of 85 % reaches with probability
≤ 5 % (scipy.stats.binom). For 60 claims that is 4 misses: P(pass | 85 %) = 0.042,
P(pass | 95 %) = 0.82, P(pass | 97.5 %) = 0.98. Measured (docs/coverage_realistic.py, 40 shots,
2026-11-29): at most one miss per figure in every world.
"""

from __future__ import annotations

import os

import pytest
from scipy.stats import binom

from tests.realistic_study import coverage, run_study, table
from tests.studies.binomial import max_misses

pytestmark = pytest.mark.study

SHOTS = 60
DRAWS = 100  # as the suite's study and a rig's shot
REJECTED = 0.85  # issue 40 item 2: "with each effect alone, coverage is at least 85 %"
EFFECTS = ("transverse", "asymmetry", "onset", "ringing")
MAIN = ("sensitivity", "natural_frequency_hz", "damping_ratio", "fbsd_5", "fbsd_10")  # claimed on every bar
_studies: dict[str, dict] = {}


def _coverage(effect: str) -> dict:
    """The world's coverage table, computed once per module run."""
    if effect not in _studies:
        _studies[effect] = coverage(run_study(effect, SHOTS, draws=DRAWS, workers=os.cpu_count() or 1))
    return _studies[effect]


def test_the_threshold_has_the_stated_power() -> None:
    k = max_misses(SHOTS, REJECTED)
    assert k == 4
    assert binom.cdf(k, SHOTS, 1.0 - REJECTED) <= 0.05  # a coverage of 85 % fails with probability ≥ 95 %
    assert binom.cdf(k, SHOTS, 0.05) >= 0.8  # a calibrated 95 % interval passes with 0.82
    assert binom.cdf(k + 1, SHOTS, 1.0 - REJECTED) > 0.05  # and no larger count would do


@pytest.mark.parametrize("effect", EFFECTS)
def test_each_interval_holds_the_truth_with_each_effect_alone(effect: str) -> None:
    rows = _coverage(effect)
    print(table(rows, f"{effect} alone: {SHOTS} shots, {DRAWS} draws"))  # the figures, with `pytest -s`
    # ε is judged where the mount has it: elsewhere its truth is 0 and it is claimed on a shot or
    # two, too few for any count of misses to reject 85 % (max_misses is −1 below 19 claims)
    judged = (*MAIN, "asymmetry") if effect == "asymmetry" else MAIN
    for name in judged:
        assert rows[name].claims >= 0.9 * SHOTS, rows[name]  # determined on (nearly) every shot
    failing = {name: f"{rows[name].holds} of {rows[name].claims}" for name in judged
               if rows[name].claims - rows[name].holds > max_misses(rows[name].claims, REJECTED)}
    assert not failing, f"{effect} alone: {failing}"
