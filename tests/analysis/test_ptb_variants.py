"""Issue 17 item 3: the intervals hold the sine calibration's values on variants of PTB's record
too, not only on the file as published: another sample rate, a shorter capture, a skew between
the channels, more noise. The truth is independent (the sine calibration of the same sensor);
the variants are made the way a lab's other recordings of the same shot would differ."""

from __future__ import annotations

import pytest
from hopkinson.analysis.params import AnalysisParams
from hopkinson.analysis.shot_analysis import analyse_record

from tests.ptb_shock import against_sine, cut, decimated, noisier, skewed

DRAWS = 60


VARIANTS = {
    "5 MS/s": lambda: decimated(2),
    "2 MS/s": lambda: decimated(5),
    "1.2 ms capture": lambda: cut(12_000),
    "skew +0.3 us": lambda: skewed(3),
    "skew -0.3 us": lambda: skewed(-3),
    "skew +0.8 us": lambda: skewed(8),
    "0.1 % more noise": lambda: noisier(1e-3),
    "0.2 % more noise": lambda: noisier(2e-3, seed=2),
    "0.5 % more noise": lambda: noisier(5e-3),
}
# Known misses, each strict: when one starts to pass, its mark must go.
MISSES = {
    "0.9 ms capture": (lambda: cut(9_000), "cut while the response still rings at 2-3 % of the peak: the all-pole "
                       "fit's resonance sits at 43 kHz (50 on the whole record), both edges ~15 % low"),
    "0.8 ms capture": (lambda: cut(8_000), "cut in the bar's motion after the pulse (2-3 % of the peak, the sensor "
                       "seeing x0.75 of it): the DC gain's interval is -5.4 … +1.8 %, wider than the issue's 2 %"),
    "0.75 ms capture": (lambda: cut(7_500), "cut in the bar's motion after the pulse: the FBSD ±5 % interval "
                        "holds the sine's edge but its half-width is 26 % of the value, over the issue's 25 %"),
}
# Measured (stop 32) on captures cut every 0.02 ms from 0.6 to 0.92 ms: the nominal FBSD ±5 % edge moves
# between 9.2 and 11.7 kHz with where the capture ends (the whole record: 10.9; the sine: 11.4). The
# window's end is not the cause on its own (refitting the 0.9 ms fit on shorter windows keeps it at
# 9.6 kHz): the model error's weights, measured on the free structure's residual, change with it.


def holds_the_sine(make) -> None:
    judged = against_sine(analyse_record(make(), AnalysisParams(draws=DRAWS, seed=1)).uncertainty)
    for figure, j in judged.items():
        assert j["contains"] and j["half_width_ok"], (figure, j)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_the_intervals_hold_the_sine_calibration_on_a_variant(name):
    holds_the_sine(VARIANTS[name])


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=why))
                                  for n, (_, why) in MISSES.items()])
def test_the_known_misses_still_miss(name):
    holds_the_sine(MISSES[name][0])
