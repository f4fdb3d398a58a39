"""analysis.uncertainty (GUM Supplement 1 Monte Carlo) against a known simulated truth.

The coverage study: many shots of one simulated sensor (27 kHz, ζ = 0.05; a 20 µs half-sine at
10 MS/s, 2 % noise on both channels, analysed at 1 MS/s), each with its own noise; about 95 %
of the 95 % intervals must contain the truth, and the intervals must not be needlessly wide:
their mean width is compared with 2 × 1.96 × the spread of the estimates over the shots.
The reference chain is set to zero there (its contribution is exact and is tested apart).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hopkinson.analysis.identify import identify
from hopkinson.analysis.params import AnalysisParams
from hopkinson.analysis.uncertainty import UncertaintyOptions, evaluate, shot_uncertainty

from tests.analysis.hard_records import Case, record, truth_figures

NO_CHAIN = dict(u_grating_pitch_rel=0.0, u_interferometer_rel=0.0, u_amp_gain_rel=0.0, u_digitizer_gain_rel=0.0,
                channel_skew_s=0.0)
CASE = Case(reference_noise=0.02, response_noise=0.02, samples=10_000)
SHOTS = 36
DRAWS = 100


def _figures(result) -> dict[str, object]:
    return {"dc_gain": result.dc_gain, "natural_frequency_hz": result.natural_frequency_hz,
            "damping_ratio": result.damping_ratio, "fbsd_5": result.fbsd_hz["5"], "fbsd_10": result.fbsd_hz["10"],
            "shock_sensitivity": result.shock_sensitivity}


@pytest.fixture(scope="module")
def study() -> dict[str, dict[str, list[float]]]:
    out: dict[str, dict[str, list[float]]] = {}
    for shot in range(SHOTS):
        ident = identify(record(CASE, 1000 + shot))
        result = evaluate(ident, UncertaintyOptions(draws=DRAWS, seed=shot, **NO_CHAIN))
        for name, e in _figures(result).items():
            row = out.setdefault(name, {"value": [], "lo": [], "hi": [], "u": []})
            row["value"].append(e.value)
            row["lo"].append(e.interval[0])
            row["hi"].append(e.interval[1])
            row["u"].append(e.u)
    return out


def test_about_95_percent_of_the_intervals_contain_the_truth(study) -> None:
    truth = truth_figures(CASE)
    inside = {name: np.mean([lo <= truth[name] <= hi for lo, hi in zip(row["lo"], row["hi"], strict=True)])
              for name, row in study.items()}
    overall = float(np.mean(list(inside.values())))
    assert 0.90 <= overall <= 0.99, inside  # measured 0.96 (100 shots: 0.94–1.00 per figure)
    assert min(inside.values()) >= 0.80, inside


def test_the_intervals_are_not_needlessly_wide(study) -> None:
    """The typical (median) interval width against the width the spread of the estimates over the
    shots calls for (2 × 1.96 sd), and the median u against that sd: both near 1."""
    for name, row in study.items():
        spread = float(np.std(row["value"], ddof=1))
        width = float(np.median(np.array(row["hi"]) - np.array(row["lo"])))
        assert 0.6 < width / (2 * 1.96 * spread) < 1.7, (name, width / (2 * 1.96 * spread))
        assert 0.6 < float(np.median(row["u"])) / spread < 1.7, name


def test_reference_chain_adds_in_quadrature_to_the_dc_gain() -> None:
    ident = identify(record(CASE, 7))
    noise_only = evaluate(ident, UncertaintyOptions(draws=DRAWS, seed=1, **NO_CHAIN))
    chain = evaluate(ident, UncertaintyOptions(draws=DRAWS, seed=1))
    expected = math.sqrt((noise_only.dc_gain.u / noise_only.dc_gain.value) ** 2 + 1e-4**2 + 5e-4**2 + 2e-3**2 + 2e-3**2)
    assert chain.dc_gain.u / chain.dc_gain.value == pytest.approx(expected, rel=0.2)
    budget = {b["source"]: b for b in chain.to_dict()["budget"]}
    assert budget["amplifier gain"]["u_rel"] == 2e-3 and budget["grating pitch"]["u_rel"] == 1e-4
    # The chain scales the sensitivity only: f_n's interval is the same with or without it.
    assert chain.natural_frequency_hz.u == pytest.approx(noise_only.natural_frequency_hz.u, rel=0.2)


def test_draws_are_reproducible_from_the_seed_and_feed_the_dcm() -> None:
    ident = identify(record(CASE, 8))
    a = evaluate(ident, UncertaintyOptions(draws=60, seed=3))
    b = evaluate(ident, UncertaintyOptions(draws=60, seed=3))
    assert a.to_dict() == b.to_dict() and a.seed == 3
    assert len(a.model_draws) == a.draws and all(m.is_stable for m in a.model_draws)


def test_a_failed_uncertainty_keeps_the_values_and_warns() -> None:
    ident = identify(record(CASE, 9))
    ident.context = None  # e.g. an identification rebuilt from a file
    warnings: list[str] = []
    data, draws = shot_uncertainty(ident, AnalysisParams(), None, warnings)
    assert data is None and draws == []
    assert len(warnings) == 1 and "could not be evaluated" in warnings[0]
    warnings.clear()
    assert shot_uncertainty(ident, AnalysisParams(uncertainty=False), None, warnings) == (None, [])
    assert "switched off" in warnings[0]
