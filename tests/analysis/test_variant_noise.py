"""A Type B row's variant shift less the part the record's noise explains (analysis.systematics
`beyond_noise`, Hausman), and the linearised noise variance it subtracts
(analysis.uncertainty_budget `noise_variances`), against independent truths: closed forms, and
the scatter of the figures over independent noise records of a known sensor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hopkinson.analysis.identify import identify
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.systematics import beyond_noise
from hopkinson.analysis.uncertainty_budget import noise_variances
from tests.analysis.hard_records import Case, record

NOMINAL = {"dc_gain": 1.0, "natural_frequency_hz": 27_000.0}


def test_a_shift_keeps_what_the_noise_does_not_explain() -> None:
    # Δ = 0.05, |u²(variant) − u²(nominal)| = 0.0009: √(0.0025 − 0.0009) = 0.04, sign kept
    out = beyond_noise(NOMINAL, {"dc_gain": 0.95, "natural_frequency_hz": 27_030.0},
                       {"dc_gain": 0.0004, "natural_frequency_hz": 100.0},
                       {"dc_gain": 0.0013, "natural_frequency_hz": 500.0})
    assert out["dc_gain"] == pytest.approx(1.0 - 0.04, abs=1e-12)
    assert out["natural_frequency_hz"] == pytest.approx(27_000.0 + math.sqrt(900.0 - 400.0), abs=1e-9)


def test_a_shift_the_noise_explains_leaves_no_row_and_a_figure_without_variance_keeps_its_shift() -> None:
    # the variances' difference (the variant's noisier by 0.01) exceeds Δ² = 0.0016: nothing left;
    # a smaller variant variance counts the same (|difference|); f_n has no variance: kept whole
    out = beyond_noise(NOMINAL, {"dc_gain": 1.04, "natural_frequency_hz": 26_990.0},
                       {"dc_gain": 0.02}, {"dc_gain": 0.01})
    assert out["dc_gain"] == 1.0
    assert out["natural_frequency_hz"] == 26_990.0
    # a variance that could not be computed (NaN) takes nothing away: the shift stays whole
    kept = beyond_noise(NOMINAL, {"dc_gain": 1.04}, {"dc_gain": 0.0001}, {"dc_gain": math.nan})
    assert kept["dc_gain"] == 1.04


SEEDS = range(3000, 3040)  # 40 independent noise records: a spread known to ±11 % (1σ)
CASE = Case(reference_noise=0.02, response_noise=0.02, samples=10_000)


def test_the_linearised_noise_variance_matches_the_scatter_over_independent_records() -> None:
    """The figures' standard deviation over 40 records of one sensor (27 kHz, ζ 0.05, 2 % noise on
    both channels), each identified at order 2, against the median of each record's linearised
    u: the same within the spread's sampling error (a ratio in [0.70, 1.35]: ±2.7σ of a standard
    deviation from 40 values). Measured: 1.00, 1.07, 0.95 (DC gain, f_n, ζ); on seeds 2000-2039
    0.89, 1.28, 0.86 and 4000-4039 1.07, 1.09, 1.01."""
    options = AnalysisOptions(order=2)
    values: dict[str, list[float]] = {"dc_gain": [], "natural_frequency_hz": [], "damping_ratio": []}
    linear: dict[str, list[float]] = {k: [] for k in values}
    for seed in SEEDS:
        ident = identify(record(CASE, seed), options)
        fit = ident.settlement.sweep.fits[ident.order]
        main = ident.main_mode
        nominal = {"dc_gain": ident.model.dc_gain, "natural_frequency_hz": main.natural_frequency_hz,
                   "damping_ratio": main.damping_ratio}
        var = noise_variances(ident, ident.settlement.data, fit, 1.0, nominal)
        for k in values:
            values[k].append(nominal[k])
            linear[k].append(math.sqrt(var[k]))
    for k in values:
        ratio = float(np.std(values[k], ddof=1)) / float(np.median(linear[k]))
        assert 0.70 <= ratio <= 1.35, (k, ratio)
