"""The model's structure and how its delay is fitted: typed names, written to JSON as their values."""

from __future__ import annotations

from enum import StrEnum


class Structure(StrEnum):
    """The numerator B's structure: free (n + 1 coefficients), or all-pole, B = g·(1 + z⁻¹)ⁿ/2ⁿ
    (no finite zeros; docs/decisions/0011)."""

    FREE = "free"
    ALL_POLE = "all_pole"


class DelayMode(StrEnum):
    """How a fit's input delay τ (samples) is bounded: CAUSAL 0 ≤ τ ≤ max_delay, FREE either sign,
    FIXED held where it is given (a fit is asked for it by a number, the delay)."""

    CAUSAL = "causal"
    FREE = "free"
    FIXED = "fixed"
