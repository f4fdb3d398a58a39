"""The miss threshold of a coverage study (docs/testing.md "Statistical tests and their power")."""

from __future__ import annotations

from scipy.stats import binom

REJECTED_COVERAGE = 0.90  # what a 95 % interval's study must not pass (issue 45 item 3)


def max_misses(trials: int, rejected: float = REJECTED_COVERAGE, power: float = 0.95) -> int:
    """The most misses among `trials` that a coverage of `rejected` reaches with probability at
    most 1 − `power` (−1: no count does)."""
    k = -1
    while binom.cdf(k + 1, trials, 1.0 - rejected) <= 1.0 - power:
        k += 1
    return k


def pass_probability(trials: int, coverage: float, misses: int | None = None) -> float:
    """P(at most `misses` (default: `max_misses(trials)`) misses of `trials` | the true `coverage`)."""
    return float(binom.cdf(max_misses(trials) if misses is None else misses, trials, 1.0 - coverage))
