"""Whole numbers of samples from ratios of floats.

A ratio such as 8 µs ÷ 1 µs or 250 MS/s ÷ 10 MS/s is a whole number on paper but not in
floating point: 1 / (1 / 250e6) is 249999999.99999997, so int(fs // 10e6) gives 24, not 25. Each
count here rounds the ratio to COUNT_DIGITS decimals first, which no sample count of a record
can need, then takes its floor or ceiling.
"""

from __future__ import annotations

import math

COUNT_DIGITS = 6


def floor_count(ratio: float) -> int:
    """⌊ratio⌋ with `ratio` rounded to COUNT_DIGITS decimals first (24.999999999999996 is 25)."""
    return int(math.floor(round(ratio, COUNT_DIGITS)))


def ceil_count(ratio: float) -> int:
    """⌈ratio⌉ with `ratio` rounded to COUNT_DIGITS decimals first (8.000000000000002 is 8)."""
    return int(math.ceil(round(ratio, COUNT_DIGITS)))
