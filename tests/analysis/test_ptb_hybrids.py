"""Issue 17 and issue 40 on the hybrids (tests/analysis/ptb_hybrids.py): PTB's real reference
drives a known sensor (55 kHz, ζ 0.03), clean, with a real-shaped disturbance injected (a gain
that differs between the pulse's lobes, the bar's motion after the pulse reaching the sensor):
the mode is claimed between the pulse's spectral nulls, the lobe gain is measured as the
asymmetry ε, the motion is corrected and carried, and the intervals contain the known sensor.
PTB's own record is test_ptb_identify.py's.

Seeds not picked to pass (issue 45 item 3). Each hybrid is identified once per session
(tests/analysis/ptb_fixtures.py) and its Monte Carlo drawn on seeds fixed before any result was
seen; containment is counted with a stated threshold, whose pass probabilities (scipy.stats.binom)
test_ptb_identify.py's `test_the_thresholds_have_the_stated_power` asserts:

- Each of HYBRIDS on each of HYBRID_SEEDS (60 draws): the FBSD ±5 % and ±10 % edges, the
  sensitivity, f_n, ζ and the response band throughout the supported band, and ε where the
  lobes' gains differ: 99 trials, at most HYBRID_MAX_MISSES = 4 misses. Taken as independent
  trials, P(pass | 90 %) = 0.025, P(pass | 95 %) = 0.44, P(pass | 99 %) = 0.997. But each
  hybrid's data (its 0.01 % response noise) is one fixed draw, so the seeds vary the Monte Carlo
  only: a guard within the suite's time, not a coverage over data. That, with the power to reject
  90 % (P(pass | 90 %) = 0.041 per figure, 78 identifications), is
  tests/studies/test_ptb_hybrids_coverage_powered.py, run by `make studies` (CI). The count here
  names every miss (measured on these: none of 99; seeds 1–8, none of 264).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from tests.analysis.ptb_fixtures import seeds
from tests.analysis.ptb_hybrids import (
    F_N_HZ,
    HYBRID_MAX_MISSES,
    HYBRID_SEEDS,
    HYBRIDS,
    TRUTH,
    epsilon_truth,
    hybrid,
    hybrid_holds,
    truth_fbsd_hz,
)


def test_the_hybrids_intervals_hold_the_known_sensor(analyses):
    """Every figure of every hybrid on each of HYBRID_SEEDS: at most HYBRID_MAX_MISSES misses of
    99 (module docstring); a figure the hybrid does not report counts as a miss."""
    misses = [(case, seed, name) for case in HYBRIDS for seed in HYBRID_SEEDS
              for name, held in hybrid_holds(hybrid(analyses, case, seed), HYBRIDS[case][1]).items() if not held]
    assert len(misses) <= HYBRID_MAX_MISSES, misses


@pytest.mark.parametrize("case", list(HYBRIDS))
def test_a_hybrids_mode_is_claimed_between_the_nulls(analyses, case):
    """Issue 40 item 4: the 55 kHz mode lies between the pulse's spectral nulls (its stretches
    45.3-51.1 and 53.6-60.5 kHz, a null between): the band runs across the nulls, so the mode is
    claimed, within 0.5 %, and its f_n and ζ carry intervals within physical bounds (until issue
    40 the band stopped at the first null, 28 kHz, and the mode was only bounded from below)."""
    analysis = hybrid(analyses, case, HYBRID_SEEDS[0])
    ident = analysis.identification
    assert ident.supported_band_hz[1] > F_N_HZ and len(ident.supported_band.intervals_hz) > 1
    main = ident.main_mode
    assert main is not None and abs(main["natural_frequency_hz"] / F_N_HZ - 1) < 0.005, main
    for seed in HYBRID_SEEDS:
        u = hybrid(analyses, case, seed).uncertainty["main_mode"]
        assert u["natural_frequency_hz"]["interval"][0] > 0 and u["damping_ratio"]["interval"][0] >= 0, u


def test_a_hybrid_with_the_real_reference_is_recovered(analyses):
    ident = hybrid(analyses, "clean", HYBRID_SEEDS[0]).identification
    assert ident.noise.motion_after_pulse  # the real reference's motion, seen by both channels
    assert not ident.noise.model_error.significant  # a linear sensor: nothing beyond the noise


@pytest.mark.parametrize("case", ["lobe", "lobe x0.25", "lobe x2"])
def test_a_lobe_dependent_gain_is_measured_as_the_asymmetry(analyses, case):
    """Issue 40 item 1: the gain that differs between the pulse's lobes (issue 17 measured ×0.993
    and ×1.0145 on PTB's record; here also a quarter and twice that) is fitted as ε, not weighed
    and drawn as model error (issue 17: before that, "no order gives a stable model"): no model
    error is left, and on every seed ε's interval excludes zero (the asymmetry is resolved) and,
    at the measured asymmetry and twice it, is narrower than the asymmetry it measures (its
    containment is counted above)."""
    tension, compression = HYBRIDS[case][1]
    assert not hybrid(analyses, case, HYBRID_SEEDS[0]).identification.noise.model_error.significant
    for seed in HYBRID_SEEDS:
        u = hybrid(analyses, case, seed).uncertainty
        lo, hi = u["input_terms"]["asymmetry"]["interval"]
        assert 0 < lo, (seed, lo, hi)  # the asymmetry is resolved
        if case != "lobe x0.25":  # the measured one and twice it: resolved to better than its size
            assert hi - lo < epsilon_truth(tension, compression), (seed, lo, hi)


def _runaway_seeds(analyses, case: str, seeds_: list[int] = HYBRID_SEEDS) -> list[tuple[int, str, float, float]]:
    """The (seed, level, low, high) of the FBSD intervals wider than issue 17's half-width (25 % of the edge)."""
    out = []
    for seed in seeds_:
        u = hybrid(analyses, case, seed).uncertainty
        for level, edge in truth_fbsd_hz(TRUTH).items():
            lo, hi = u["fbsd_hz"][level]["interval"]
            if (hi - lo) / 2 > 0.25 * edge:
                out.append((seed, level, lo, hi))
    return out


# Until the draws' candidate orders left out an order whose fit holds a real pole cancelled by a
# zero (analysis.uncertainty_draws._order_assignment), about 1 seed in 8 per case ran away: 3-5
# of 60 draws refitted at order 3 (order 2 plus a pole-zero pair below the lowest bin) put the
# FBSD edges at 20-50 Hz and the reflected intervals reached 20-250 kHz (±5 %: x0.25 [11.7,
# 244] kHz). Held at most on one seed of the three: were the rate 1/8, two or more of three
# seeds run away with probability 0.043; a regression that lets it come on most seeds fails at once.
RUNAWAY_RATE = 1 / 8
LOBES = ["lobe", "lobe x0.25", "lobe x2"]
RUNAWAY_SEEDS = seeds(1, 8)  # the lobe hybrids' runs counted together: 24 trials


@pytest.mark.parametrize("case", list(HYBRIDS))
def test_the_hybrids_fbsd_intervals_run_away_on_at_most_one_seed(analyses, case):
    """Issue 17's half-width (25 % of the edge) on all seeds but at most one."""
    assert binom.sf(1, len(HYBRID_SEEDS), RUNAWAY_RATE) <= 0.05
    assert len({seed for seed, *_ in _runaway_seeds(analyses, case)}) <= 1, _runaway_seeds(analyses, case)


@pytest.mark.parametrize("case", list(HYBRIDS))
def test_the_hybrids_fbsd_intervals_are_as_narrow_as_the_issue_asks(analyses, case):
    """Issue 17's half-width (25 % of the edge) on every seed."""
    assert _runaway_seeds(analyses, case) == []


def test_the_lobe_hybrids_fbsd_intervals_never_run_away_over_eight_seeds(analyses):
    """Issue 40 item 3 (no impossible claims): the lobe-gain hybrids, where the order-3 draws ran
    away, on each of RUNAWAY_SEEDS: no interval wider than issue 17's half-width. Were the
    runaway rate still RUNAWAY_RATE, all 24 runs would pass with probability 0.041 (measured:
    none of 24, and none of 32 with the clean hybrid)."""
    runs = len(LOBES) * len(RUNAWAY_SEEDS)
    assert binom.pmf(0, runs, RUNAWAY_RATE) <= 0.05
    assert [(case, *r) for case in LOBES for r in _runaway_seeds(analyses, case, RUNAWAY_SEEDS)] == []


def test_motion_that_differs_between_the_channels_is_corrected_and_carried(analyses):
    """The sensor sees the bar's motion after 0.7 ms at ×0.75: the motion term (analysis.input_terms,
    from the pulse's end on) takes most of it (γ below zero, above the −0.25 injected on a window
    the term does not share), what it cannot follow is model error (not noise); its intervals'
    containment of the known sensor is counted above."""
    assert hybrid(analyses, "motion", HYBRID_SEEDS[0]).identification.noise.model_error.significant
    for seed in HYBRID_SEEDS:
        lo, hi = hybrid(analyses, "motion", seed).uncertainty["input_terms"]["motion after the pulse"]["interval"]
        assert -0.25 < lo <= hi < 0.0, (seed, lo, hi)


@pytest.mark.parametrize("case", list(HYBRIDS))
def test_the_response_band_is_ordered(analyses, case):
    for seed in HYBRID_SEEDS:
        band = hybrid(analyses, case, seed).uncertainty["response_band"]
        middle = np.array(band["magnitude_rel"])
        assert np.all(np.array(band["magnitude_rel_low"]) <= middle) and np.all(middle <= band["magnitude_rel_high"])
