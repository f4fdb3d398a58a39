"""Issue 17 item 3: the intervals hold the sine calibration's values on variants of PTB's record
too, not only on the file as published: another sample rate, a shorter capture, a skew between
the channels, more noise. The truth is independent (the sine calibration of the same sensor);
the variants are made the way a lab's other recordings of the same shot would differ.

Seeds not picked to pass (issue 45 item 3): variant i (in the order of VARIANTS) draws its
DRAWS Monte Carlo draws with seed FIRST_SEED + i, a rule fixed before any result was seen. Each
variant's three intervals (FBSD ±5 %, ±10 %, the sensitivity) are three trials, 78 in all, and
the variants pass together with at most MAX_MISSES = 3 misses (7 until the studies; measured: 0
of 78). Power (scipy.stats.binom, asserted in `test_the_threshold_has_the_stated_power`), the
trials taken as independent: P(pass | 90 %) = 0.041, P(pass | 95 %) = 0.45, P(pass | 99 %) = 0.99.
The trials are not independent (one shot, one truth: a bias
on PTB's record would miss on many variants at once, which this count catches, not excuses).
Each variant's half-widths stay within issue 17's (25 %, 2 %) on its own seed.
"""

from __future__ import annotations

import pytest
from scipy.stats import binom

from tests.analysis.ptb_fixtures import Analyses
from tests.ptb_shock import against_sine, cut, decimated, noisier, skewed, started_late
from tests.studies.binomial import max_misses

# 150 draws (60 before decision 0025): the 95 % interval's ends at ranks (M + 1)p lie at the
# 3.8th draw from each end. At 60 the honest ends are the 1.5th (NumPy's default ranks took the
# 2.5th and held 93 %), and four variants' DC gain or FBSD ±10 % half-widths exceeded issue 17's
# 2 % and 25 % (2.1 %, 27 %); at 100, the 0.65 ms capture's FBSD ±5 % read 25.1 %.
DRAWS = 150
FIRST_SEED = 1
MAX_MISSES = 3  # tests.studies.binomial.max_misses(78)

VARIANTS = {
    "5 MS/s": lambda: decimated(2),
    "2 MS/s": lambda: decimated(5),
    "1.2 ms capture": lambda: cut(12_000),
    "0.9 ms capture": lambda: cut(9_000),
    "0.8 ms capture": lambda: cut(8_000),
    "0.75 ms capture": lambda: cut(7_500),
    # 14 bins: the model error was measured on an order that took 20 of the 28 real residuals and
    # read too small; every interval was too wide until stop 38 (identify.fit_weighing_model_error)
    "0.65 ms capture": lambda: cut(6_500),
    "skew +0.3 us": lambda: skewed(3),
    "skew -0.3 us": lambda: skewed(-3),
    "skew +0.8 us": lambda: skewed(8),
    "0.1 % more noise": lambda: noisier(1e-3),
    "0.2 % more noise": lambda: noisier(2e-3, seed=2),
    "0.5 % more noise": lambda: noisier(5e-3),
    # 1 % of the peak, four noises that missed until stop 35: the record's model error, partly masked
    # by the noise, read 2.2-3.8× what the noise explains, under the detection's 4× then: seed 12 took
    # a resonance at 29.5 kHz (±5 % edge 16.8 kHz), seed 13 claimed a mode at 27.8 kHz inside the band,
    # seed 6's intervals drew neither the model error nor the band's parts (12.0 [11.67, 12.90] kHz);
    # seed 5's free fit holds a doublet and reads 2.17×: it misses with that fit's threshold at 2.5×
    # (model_error.MODEL_ERROR_WITH_DOUBLET, now 1.5×), the ±10 % interval [15.53, 17.38] kHz
    "1 % more noise (seed 5)": lambda: noisier(1e-2, seed=5),
    "1 % more noise (seed 6)": lambda: noisier(1e-2, seed=6),
    "1 % more noise (seed 12)": lambda: noisier(1e-2, seed=12),
    "1 % more noise (seed 13)": lambda: noisier(1e-2, seed=13),
    # 2 % of the peak, two of four noises that missed until stop 36: the bar's motion after the pulse
    # was found only from 1.13-1.19 ms on (the noise hides its coherence), the head before it taken as
    # quiet read the reference's noise ×1.3-1.6 too high, and the band stopped at 20 kHz instead of 28
    "2 % more noise (seed 3)": lambda: noisier(2e-2, seed=3),
    "2 % more noise (seed 6)": lambda: noisier(2e-2, seed=6),
    # seed 5 chose free order 1 (V 23.8) over all-pole order 2 (V 10.5), both with 4 parameters: of two
    # structures with as many, the free one stood by default until stop 37 (±10 % interval [12, 18 600]
    # kHz); the lower cost stands now (order_search._all_pole_preferred)
    "2 % more noise (seed 5)": lambda: noisier(2e-2, seed=5),
    # seed 12 missed while the lead-in reached the pulse's foot on every record (a step of stop 37):
    # its noise read 3 % lower, one more bin entered the band, the free orders 1-2 became unstable
    # once converged and order 3, its fit stopped short of converging, was taken (±5 % edge 9.93
    # [9.05, 10.83] kHz)
    "2 % more noise (seed 12)": lambda: noisier(2e-2, seed=12),
    # A capture started 0.2 ms later: the pulse's foot 0.16 ms in. Until stop 37 the lead-in at rest
    # ended where the pulse's busy stretch, widened by twice its width and the delay for the window's
    # margins, began: none was left, the reference's noise was measured on the bar's motion after
    # the pulse (×11), the band stopped at 20 kHz and the ±5 % edge read 10.0 [8.45, 11.02] kHz.
    # The lead-in now reaches the pulse's foot (record_preparation._lead_in_end).
    "started 0.2 ms later": lambda: started_late(2_000),
    # at 0.25 MS/s the margins (twice the pulse's width and 32 samples of delay, 128 µs) left no lead-in
    # either: ±5 % edge 9.72 [5.83, 9.99] kHz until stop 37
    "0.25 MS/s": lambda: decimated(40),
    "started 0.2 ms later, 1 % more noise (seed 21)": lambda: started_late(2_000, noisier(1e-2, seed=21)),
    # several differences at once
    "2 MS/s, 0.8 ms capture": lambda: cut(1_600, decimated(5)),
    "5 MS/s, skew +0.5 us, 0.3 % more noise": lambda: decimated(2, noisier(3e-3, 4, skewed(5))),
}
# The captures of 0.75-0.9 ms missed until stop 33: the nominal FBSD ±5 % edge moved between 9.2 and
# 11.7 kHz with where the capture ended, because the model error's weights were read per bin from one
# residual (~2 degrees of freedom a bin) and followed its noise; its spectrum has two parameters now
# (c·|U|^(2β), analysis.model_error), measured again on the final model, and the edge stays within
# 11.2-11.35 kHz on them.


SEED = {name: FIRST_SEED + i for i, name in enumerate(VARIANTS)}
FIGURES = ("fbsd_5", "fbsd_10", "dc_gain")


def judged_on(analyses: Analyses, name: str) -> dict[str, dict]:
    """The variant's intervals beside the sine calibration's values, on the variant's own seed."""
    return against_sine(analyses.analysed(name, VARIANTS[name], SEED[name], DRAWS).uncertainty)


def test_the_threshold_has_the_stated_power() -> None:
    trials = len(VARIANTS) * len(FIGURES)
    assert trials == 78
    assert MAX_MISSES == max_misses(trials)
    assert binom.cdf(MAX_MISSES, trials, 0.10) <= 0.05  # 0.041 at 90 %
    assert binom.cdf(MAX_MISSES, trials, 0.01) >= 0.99  # 0.992 at 99 %


@pytest.mark.parametrize("name", list(VARIANTS))
def test_the_intervals_are_as_narrow_as_the_issue_asks_on_a_variant(analyses, name):
    for figure, j in judged_on(analyses, name).items():
        assert j["half_width_ok"], (figure, j)


def test_the_intervals_hold_the_sine_calibration_on_the_variants(analyses):
    misses = [(name, figure, j["interval"], j["truth"]) for name in VARIANTS
              for figure, j in judged_on(analyses, name).items() if not j["contains"]]
    assert len(misses) <= MAX_MISSES, misses
