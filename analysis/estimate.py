"""A figure with its uncertainty (GUM Supplement 1): the value, its standard uncertainty and its
95 % coverage interval, or why the shot does not determine it. One type for the Monte Carlo's
results (`Estimate.of_draws`), the key figures, the reports and the lab record.

Invariants every interval from draws keeps: it contains its own value, and a figure bounded by
physics stays inside its bound (a frequency or a damping ratio above zero, a DC gain of the
value's sign): such a figure's draws are reflected on a log scale. A figure the record cannot
determine is not given a number with an absurd interval: `Estimate.undetermined` says why.
Light: NumPy is imported only to evaluate draws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

COVERAGE = 0.95


@dataclass(frozen=True)
class Estimate:
    """A value with its standard uncertainty and 95 % coverage interval (None: without), or the
    reason the shot does not determine it (value None then)."""

    value: float | None
    u: float | None = None
    interval: tuple[float, float] | None = None
    not_determined: str | None = None

    @property
    def expanded(self) -> float | None:
        """U: half the width of the 95 % coverage interval (k ≈ 2 for a normal distribution)."""
        if self.interval is None:
            return None
        return 0.5 * (self.interval[1] - self.interval[0])

    @property
    def u_rel(self) -> float | None:
        if self.u is None or not self.value:
            return None
        return abs(self.u / self.value)

    def format(self, scale: float = 1.0, digits: int = 4, unit: str = "") -> str:
        """'27.01 ± 0.12 kHz' (value ± U, 95 %), or the value alone without uncertainty; "not
        determined" where the shot does not determine it."""
        if self.not_determined:
            return "not determined"
        if self.value is None:
            return "—"
        suffix = f" {unit}" if unit else ""
        big = self.expanded
        if big is None:
            return f"{self.value / scale:.{digits}g}{suffix}"
        # As many decimals as the two significant digits of U need (GUM 7.2.6).
        decimals = _decimals_for(big / scale)
        return f"{self.value / scale:.{decimals}f} ± {big / scale:.{decimals}f}{suffix}"

    def to_dict(self) -> dict[str, Any]:
        """{"value", "u", "interval"} (inf and NaN as None), and "not_determined" when set."""
        interval = None if self.interval is None else [_finite(self.interval[0]), _finite(self.interval[1])]
        out = {"value": _finite(self.value), "u": _finite(self.u), "interval": interval}
        if self.not_determined:
            out["not_determined"] = self.not_determined
        return out

    @classmethod
    def of(cls, data: Any) -> Estimate | None:
        """From a number, a {"value", "u", "interval"} dict (`to_dict`'s), or None."""
        if data is None:
            return None
        if isinstance(data, dict):
            value = finite_number(data.get("value"))
            interval = data.get("interval")
            pair = None
            if isinstance(interval, (list, tuple)) and len(interval) == 2:
                lo, hi = finite_number(interval[0]), finite_number(interval[1])
                pair = (lo, hi) if lo is not None and hi is not None else None
            why = data.get("not_determined")
            return cls(value, finite_number(data.get("u")), pair, str(why) if why else None)
        return cls(finite_number(data))

    def with_value(self, value: float | None) -> Estimate:
        """The same uncertainty around another reported value (the value elsewhere wins)."""
        return Estimate(value, self.u, self.interval, self.not_determined)

    @classmethod
    def undetermined(cls, reason: str) -> Estimate:
        """A figure the shot does not determine (analysis.determination), with why."""
        return cls(None, None, None, reason)

    @classmethod
    def of_draws(cls, value: float, draws: np.ndarray, coverage: float = COVERAGE,
                 reflect: np.ndarray | None = None, positive: bool = False, signed: bool = False) -> Estimate:
        """u: the draws' standard deviation. Interval: the probabilistically symmetric one of
        the draws (GUM-S1 §7.7), reflected about `value`: each draw perturbs data that already
        carry noise, so the draws sit around the estimate as the estimate sits around the
        truth — with the estimator's own (second-order) bias once more; reflecting puts the
        interval where the truth lies (the basic bootstrap interval; identical for a
        symmetric distribution).

        `reflect` (one flag per draw; None: all) marks the draws that sit around the estimate
        in that sense. A draw that landed on another delay branch (Refitter.fit_branch) is not
        one: it is the other estimate the same estimator gives on data like these, a fixed
        offset from the truth rather than the estimate's scatter about it, and it is taken as it
        is (the percentile interval); reflecting it would put that offset on the wrong side.

        `positive`: a figure bounded below by zero (a frequency, a damping ratio): reflected
        about the value on a log scale (value²/draw), so the interval stays inside the bound.
        `signed`: a figure that keeps its value's sign (a DC gain): its magnitude is treated as
        `positive`, so the interval never crosses zero (docs/decisions/0021).

        The interval always contains `value`: where the draws lie all on one side of it (they do
        not bracket the estimate), the interval is extended to it."""
        import numpy as np

        if signed and value != 0:
            sign = 1.0 if value > 0 else -1.0
            mag = cls.of_draws(abs(value), sign * np.asarray(draws, dtype=float), coverage, reflect, positive=True)
            lo, hi = sorted((sign * mag.interval[0], sign * mag.interval[1]))
            return cls(float(value), mag.u, (lo, hi))
        return cls._of_draws(value, draws, coverage, reflect, positive).holding_value()

    def holding_value(self) -> Estimate:
        """The same estimate with its interval extended to hold the value (where it did not)."""
        if self.interval is None or self.value is None:
            return self
        lo, hi = self.interval
        if lo <= self.value <= hi:  # (NaN ends stay NaN: min and max keep them)
            return self
        return Estimate(self.value, self.u, (min(lo, self.value), max(hi, self.value)))

    @classmethod
    def _of_draws(cls, value: float, draws: np.ndarray, coverage: float, reflect: np.ndarray | None,
                  positive: bool) -> Estimate:
        import numpy as np

        if positive and value > 0:
            d = np.asarray(draws, dtype=float)
            d = np.where(d > 0, d, np.nan)
            est = cls._of_draws(math.log(value), np.log(d), coverage, reflect, False)
            with np.errstate(over="ignore"):
                spread = float(np.nanstd(d, ddof=1)) if np.sum(np.isfinite(d)) > 1 else math.nan
            return cls(float(value), spread, (_exp_or_inf(est.interval[0]), _exp_or_inf(est.interval[1])))
        d = np.asarray(draws, dtype=float)
        flags = np.ones(d.size, dtype=bool) if reflect is None else np.asarray(reflect, dtype=bool)
        finite = np.isfinite(d)
        d, flags = d[finite], flags[finite]
        if d.size < 2:
            return cls(value, math.nan, (math.nan, math.nan))
        u = float(np.std(d, ddof=1))
        if flags.all():
            lo, hi = coverage_ends(d, coverage)
            return cls(float(value), u, (float(2.0 * value - hi), float(2.0 * value - lo)))
        lo, hi = coverage_ends(np.where(flags, 2.0 * value - d, d), coverage)
        return cls(float(value), u, (float(lo), float(hi)))

    @classmethod
    def normal(cls, value: float, u: float) -> Estimate:
        """A normal PDF's 95 % interval (k = 1.96)."""
        k = 1.959963984540054
        return cls(float(value), float(u), (float(value - k * u), float(value + k * u)))


def coverage_ends(draws: np.ndarray, coverage: float = COVERAGE, axis: int | None = None) -> tuple[Any, Any]:
    """The ends of the probabilistically symmetric `coverage` interval of M Monte Carlo draws
    (along `axis`): the order statistics at ranks (M + 1)·(1 − coverage)/2 and (M + 1)·(1 + coverage)/2,
    interpolated (NumPy's "weibull" quantiles). Between the r-th and the (M + 1 − r)-th smallest of M
    exchangeable draws a further value of their distribution lies with probability (M + 1 − 2r)/(M + 1),
    whatever the distribution, so these ranks hold it with the coverage asked for, with the few
    hundred draws a shot affords. GUM-S1 §7.7's ranks hold it only as M grows (it asks M ≥ 10⁴/(1 − p)),
    and NumPy's default quantiles, (M − 1)·p + 1, fall short: with 150 draws a 95 % interval held
    93.8 % (tests/analysis/test_estimate_coverage.py; the 300-shot study's 92.3-95.3 %: docs/method.md,
    docs/decisions/0025)."""
    import numpy as np

    tail = 50.0 * (1.0 - coverage)
    lo, hi = np.percentile(draws, [tail, 100.0 - tail], axis=axis, method="weibull")
    return lo, hi


def _finite(value: float | None) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def finite_number(value: Any) -> float | None:
    """A finite int or float as float; anything else (a bool, text, inf, NaN) as None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) else None


def _decimals_for(expanded: float) -> int:
    """Decimals that show two significant digits of `expanded` (at least 0, at most 12)."""
    if not (expanded > 0 and math.isfinite(expanded)):
        return 4
    return int(min(12, max(0, 1 - math.floor(math.log10(expanded)))))


def _exp_or_inf(x: float) -> float:
    """exp(x) (math.exp: the goldens' bits), or inf where it passes the largest float: an
    interval end beyond it is unbounded, not an error."""
    try:
        return math.exp(x)
    except OverflowError:
        return math.inf
