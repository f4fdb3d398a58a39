"""analysis.uncertainty (GUM Supplement 1 Monte Carlo) against a known simulated truth.

The coverage study: many shots of one simulated sensor (27 kHz, ζ = 0.05; a 20 µs half-sine at
10 MS/s, 2 % noise on both channels, analysed at 1 MS/s), each with its own noise; about 95 %
of the 95 % intervals must contain the truth, and the intervals must not be needlessly wide:
their width is compared with 2 × 1.96 × the spread of the estimates over the shots (robust:
1.4826 × the median absolute deviation, as a few shots choose another order). The reference
chain is set to zero there (its contribution is exact and is tested apart).

Who runs it: the study's tests are marked `study` (`make studies`, CI after `make test`: the 140
shots took 58 s on 2 cores there, spread over a process pool); `make test` keeps the others.

What 140 shots can tell (issue 45 item 3, issue 40): each figure passes with at least
MIN_INSIDE = 133 of its 140 intervals holding the truth. Were its true coverage 90 %, it would pass
with probability P(X ≥ 133 | n = 140, p = 0.90) = 0.034 (scipy.stats.binom; ≤ 5 %); at 95 % with
0.62, at 97 % with 0.96. (Until issue 40 the test asked only that a 99 % Clopper–Pearson interval
of the rate hold 0.95: a true coverage of 90 % passed it 57 % of the time.) The DC gain's rate
must also not exceed 99 % (too wide). The finer figures
come from a 300-shot, 200-draw run of the same study (README "Calibrated"): DC gain 94.0 % (it
was 92.3 % before the noise the draws add was measured without bias), f_n 95.3 %, ζ 93.7 %,
FBSD 92.3 %, shock sensitivity 94.7 % (f_n, ζ and the shock sensitivity were 99.3–99.7 %:
too wide). On the 140 shots here (issue 40's analysis: the band across the pulse's nulls, the Type B rows;
the interval's ends at ranks (M + 1)p, docs/decisions/0025; a refitted variant's Type B shift
less what the record's noise explains, systematics.beyond_noise): DC gain 136, f_n 138, ζ 135, FBSD
±5 % and ±10 % 137, S_sh 134 of 140; the median U 2.8–3.3 × the median |error| (a Gaussian's
95 % interval: 2.97). Before beyond_noise: ζ 136, FBSD 138, the median U 3.05–3.30 × |error|. With NumPy's default ranks (93.7 % at 150 draws): DC gain 135, f_n 137,
ζ 133, FBSD 138, S_sh 134, and ζ 132 once the structure row was weighed by its evidence; before
issue 40: DC gain 133/140, ζ 127/140.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from hopkinson.analysis import uncertainty
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.findings import FindingCode
from hopkinson.analysis.identify import identify
from hopkinson.analysis.options import MIN_DRAWS, AnalysisOptions
from hopkinson.analysis.uncertainty import Estimate, evaluate, shot_uncertainty
from tests.analysis.hard_records import Case, record, truth_figures

NO_CHAIN = dict(u_grating_pitch_rel=0.0, u_interferometer_rel=0.0, u_amp_gain_rel=0.0, u_digitizer_gain_rel=0.0,
                u_channel_skew_s=0.0, transverse_motion_rel=0.0,  # the transverse row too: these records have none
                asymmetry_bound_rel=0.0)  # nor an asymmetry (their half-sine drives one direction of a symmetric sensor)
MIN_INSIDE = 133  # of SHOTS: see the module docstring for the test's power
CASE = Case(reference_noise=0.02, response_noise=0.02, samples=10_000)
SHOTS = 140
# 150 draws per shot (a 95 % interval's ends from 100 draws scatter by ~0.27 u and cost ~1.5
# points of coverage), of which 20 re-run the order choice (its PDF; 40 by default): the
# study's time goes into shots.
DRAWS = 150
ORDER_DRAWS = 20


def _figures(result) -> dict[str, object]:
    return {"dc_gain": result.dc_gain, "natural_frequency_hz": result.natural_frequency_hz,
            "damping_ratio": result.damping_ratio, "fbsd_5": result.fbsd_hz["5"], "fbsd_10": result.fbsd_hz["10"],
            "shock_sensitivity": result.shock_sensitivity}


@pytest.fixture(scope="module")
def shots() -> dict[str, object]:
    """The study's shots: each figure's values, intervals and u ("figures"), and what each
    identification read of its residual ("model_error": identify's noise report). On the
    machine's cores: each shot is a pure function of its seed (`_shot`)."""
    from concurrent.futures import ProcessPoolExecutor

    out: dict[str, dict[str, list[float]]] = {}
    model_error = []
    with ProcessPoolExecutor(os.cpu_count() or 1) as pool:
        for figures, noise in pool.map(_shot, range(SHOTS)):
            model_error.append(noise)
            for name, e in figures.items():
                row = out.setdefault(name, {"value": [], "lo": [], "hi": [], "u": []})
                row["value"].append(e.value)
                row["lo"].append(e.interval[0])
                row["hi"].append(e.interval[1])
                row["u"].append(e.u)
    return {"figures": out, "model_error": model_error}


def _shot(shot: int) -> tuple[dict[str, Estimate], dict]:
    """One shot of the study (its record's noise seeded by 1000 + shot, its draws by shot): each
    figure's estimate, and identify's model error report."""
    ident = identify(record(CASE, 1000 + shot))
    result = evaluate(ident, AnalysisOptions(draws=DRAWS, order_draws=ORDER_DRAWS, seed=shot, **NO_CHAIN))
    return _figures(result), ident.noise.model_error.to_dict()


@pytest.fixture(scope="module")
def study(shots) -> dict[str, dict[str, list[float]]]:
    return shots["figures"]


def _robust_spread(values: list[float]) -> float:
    v = np.asarray(values, dtype=float)
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def test_the_test_rejects_a_coverage_of_90_percent() -> None:
    """The design's power, as the module docstring states it."""
    from scipy.stats import binom

    assert binom.sf(MIN_INSIDE - 1, SHOTS, 0.90) <= 0.05
    assert binom.sf(MIN_INSIDE - 1, SHOTS, 0.97) >= 0.9


@pytest.mark.study
def test_about_95_percent_of_the_intervals_contain_the_truth(study) -> None:
    """Each figure's intervals hold the truth in at least MIN_INSIDE of the shots (a true coverage
    of 90 % passes with probability 0.034); the sensitivity (DC gain), the certificate's headline,
    not in more than 99 % (too wide)."""
    truth = truth_figures(CASE)
    rates = {}
    for name, row in study.items():
        inside = sum(lo <= truth[name] <= hi for lo, hi in zip(row["lo"], row["hi"], strict=True))
        rates[name] = inside
    assert all(inside >= MIN_INSIDE for inside in rates.values()), rates
    assert rates["dc_gain"] <= 0.99 * SHOTS, rates


@pytest.mark.study
def test_a_right_model_is_rarely_taken_for_model_error(shots) -> None:
    """The study's sensor is in the fitted family, so its residual is noise alone. Measured over
    the 140 shots (stop 35): median 0.69× what the noise explains, all but one below 1.4×; that
    one reads 3.2×, its response noise measured on 91 samples (7.6 degrees of freedom). The
    detection's 2× (model_error.MODEL_ERROR_DETECTED; 4× until stop 35, when PTB's record with
    1 % more noise read 2.2–3.8× and went undetected) flags it: a false-alarm rate near 1 %.
    The shots are fixed (seeds 1000–1139), so the count is exact; more than 2 of 140 would mean
    a threshold low enough to widen right models' intervals needlessly."""
    detected = sum(bool(m["detected"]) for m in shots["model_error"])
    ratios = [m["residual_over_noise"] for m in shots["model_error"]]
    assert detected <= 2, sorted(ratios)[-5:]
    assert 0.5 < float(np.median(ratios)) < 1.0, np.median(ratios)  # the noise explains it (the fit's look errs high)


@pytest.mark.study
def test_the_intervals_are_not_needlessly_wide(study) -> None:
    """The typical (median) interval width against the width the spread of the estimates over the
    shots calls for (2 × 1.96 × the robust spread), and the median u against that spread: near
    1 for every figure, within ±20 % for the DC gain (measured 0.96 on 300 shots)."""
    for name, row in study.items():
        spread = _robust_spread(row["value"])
        width = float(np.median(np.array(row["hi"]) - np.array(row["lo"]))) / (2 * 1.96 * spread)
        u = float(np.median(row["u"])) / spread
        bounds = (0.8, 1.2) if name == "dc_gain" else (0.6, 1.7)
        assert bounds[0] < width < bounds[1], (name, width)
        assert bounds[0] < u < bounds[1], (name, u)


def test_reference_chain_adds_in_quadrature_to_the_dc_gain() -> None:
    ident = identify(record(CASE, 7))
    noise_only = evaluate(ident, AnalysisOptions(draws=DRAWS, seed=1, **NO_CHAIN))
    chain = evaluate(ident, AnalysisOptions(draws=DRAWS, seed=1, asymmetry_bound_rel=0.0))
    expected = math.sqrt((noise_only.dc_gain.u / noise_only.dc_gain.value) ** 2 + 1e-4**2 + 5e-4**2 + 2e-3**2 + 2e-3**2)
    assert chain.dc_gain.u / chain.dc_gain.value == pytest.approx(expected, rel=0.2)
    # A half-sine drives one direction: the stated bound on |ε| (3 %) adds a rectangle of half it
    one_way = evaluate(ident, AnalysisOptions(draws=DRAWS, seed=1, **{**NO_CHAIN, "asymmetry_bound_rel": 0.03}))
    expected = math.hypot(noise_only.dc_gain.u / noise_only.dc_gain.value, 0.015 / math.sqrt(3))
    assert one_way.dc_gain.u / one_way.dc_gain.value == pytest.approx(expected, rel=0.2)
    assert one_way.natural_frequency_hz.u == pytest.approx(noise_only.natural_frequency_hz.u, rel=1e-9)  # a gain: the shape is not moved
    budget = {b["source"]: b for b in chain.to_dict()["budget"]}
    assert budget["amplifier gain"]["u_rel"] == 2e-3 and budget["grating pitch"]["u_rel"] == 1e-4
    # The chain scales the sensitivity only: f_n's interval is the same with or without it.
    assert chain.natural_frequency_hz.u == pytest.approx(noise_only.natural_frequency_hz.u, rel=0.2)


def test_draws_are_reproducible_from_the_seed_and_feed_the_dcm() -> None:
    # plumbing (the same seed gives the same result, every draw a stable model), not the
    # intervals' statistics: the fewest draws allowed
    ident = identify(record(CASE, 8))
    a = evaluate(ident, AnalysisOptions(draws=MIN_DRAWS, seed=3))
    b = evaluate(ident, AnalysisOptions(draws=MIN_DRAWS, seed=3))
    assert a.to_dict() == b.to_dict() and a.seed == 3
    assert len(a.model_draws) == a.draws and all(m.is_stable for m in a.model_draws)


def test_a_failed_uncertainty_keeps_the_values_and_warns(monkeypatch: pytest.MonkeyPatch) -> None:
    ident = identify(record(CASE, 9))

    def failing(*args: object, **kwargs: object) -> None:
        raise AnalysisError("no stable refit")  # the Monte Carlo failing, whatever the cause

    monkeypatch.setattr(uncertainty, "evaluate", failing)
    data, draws, found = shot_uncertainty(ident, AnalysisOptions(), None)
    assert data is None and draws == []
    assert [f.code for f in found] == [FindingCode.UNCERTAINTY_FAILED] and "could not be evaluated" in found[0].text
    data, draws, found = shot_uncertainty(ident, AnalysisOptions(uncertainty=False), None)
    assert (data, draws) == (None, []) and [f.code for f in found] == [FindingCode.UNCERTAINTY_OFF]
    assert "switched off" in found[0].text


def test_draws_on_another_delay_branch_are_taken_as_they_are_not_reflected() -> None:
    """A quarter of the draws on another branch of the delay–zeros valley, 10 u above the
    estimate: those are the other estimate of such data, not scatter about this one, so the
    interval reaches up to them (reflected they would land 10 u below, where no fit lies); the
    nominal branch's draws are reflected as before (symmetric here: the normal's quantiles)."""
    from scipy.stats import norm

    nominal = norm.ppf((np.arange(150) + 0.5) / 150)
    draws = np.concatenate([nominal, np.full(50, 10.0)])
    flags = np.concatenate([np.ones(150, dtype=bool), np.zeros(50, dtype=bool)])
    e = Estimate.of_draws(0.0, draws, reflect=flags)
    assert e.interval[1] == pytest.approx(10.0)
    assert e.interval[0] == pytest.approx(norm.ppf(0.025 / 0.75), abs=0.05)
    assert e.u == pytest.approx(np.std(draws, ddof=1))
    plain = Estimate.of_draws(0.0, nominal)
    # the 97.5 % end at rank 151·0.975 = 147.2 of the 150 (analysis.estimate.coverage_ends), the
    # normal's quantile at (147.2 − 0.5)/150
    end = norm.ppf((151 * 0.975 - 0.5) / 150)
    assert plain.interval == pytest.approx((-end, end), abs=0.02)
