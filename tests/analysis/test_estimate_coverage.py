"""analysis.estimate.coverage_ends: a Monte Carlo interval from the few hundred draws a shot
affords holds its coverage, checked by coverage over many repetitions against a known
distribution (closed form: between the r-th and the (M + 1 − r)-th of M exchangeable draws a
further value lies with probability (M + 1 − 2r)/(M + 1), whatever the distribution)."""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.analysis.estimate import Estimate, coverage_ends

REPEATS = 20_000  # the rate's standard error √(0.95·0.05/20 000) = 0.0015


def rate_inside(new: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    return float(np.mean((lo <= new) & (new <= hi)))


@pytest.mark.parametrize("draws", [50, 150, 400])
@pytest.mark.parametrize("law", ["normal", "exponential"])
def test_the_interval_of_m_draws_holds_a_further_value_95_percent_of_the_time(draws: int, law: str) -> None:
    rng = np.random.default_rng(draws)
    sample = rng.standard_normal if law == "normal" else rng.standard_exponential
    d, new = sample((REPEATS, draws)), sample(REPEATS)
    lo, hi = coverage_ends(d, 0.95, axis=1)
    # never short by more than 3.3 standard errors; the ranks are interpolated between order
    # statistics, exact at integer ranks, a little over at 50 draws (measured 95.5 %)
    assert 0.945 <= rate_inside(new, lo, hi) <= 0.96


def test_numpys_default_quantiles_fall_short_with_150_draws() -> None:
    """What the ranks correct: (M − 1)p + 1 puts the 2.5 % end at the 4.725-th of 150 draws, a
    93.7 % interval in the closed form; the corrected ends, at the 3.775-th, 95 %."""
    rng = np.random.default_rng(7)
    d, new = rng.standard_normal((REPEATS, 150)), rng.standard_normal(REPEATS)
    default = rate_inside(new, *np.percentile(d, [2.5, 97.5], axis=1))
    assert default == pytest.approx(1 - 2 * 4.725 / 151, abs=0.005)
    assert default < 0.945


def test_a_reflected_estimate_of_draws_holds_the_truth_95_percent_of_the_time() -> None:
    """The shot's case: the estimate scatters about the truth, its draws about the estimate
    (skewed: a lognormal), and Estimate.of_draws reflects them about it."""
    rng = np.random.default_rng(11)
    truth, repeats, m = 2.0, 8000, 150
    inside = 0
    for _ in range(repeats):
        value = truth + rng.standard_normal() * 0.1
        draws = value + rng.standard_normal(m) * 0.1
        lo, hi = Estimate.of_draws(value, draws).interval
        inside += lo <= truth <= hi
    assert inside / repeats == pytest.approx(0.95, abs=0.008)  # 3.3 standard errors
