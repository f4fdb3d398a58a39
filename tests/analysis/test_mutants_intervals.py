"""The uncertainty's interval logic (analysis/uncertainty.py: Estimate.of_draws, Estimate.normal,
response_band) against its definitions, on draws whose quantiles are exact: 999 evenly spaced
values, whose 2.5 % and 97.5 % points are the 25th and 975th (the ranks (M + 1)p of
analysis.estimate.coverage_ends land on a sample), and models whose responses are closed forms. These kill the mutants of the
interval logic (docs/mutation-testing.md); the coverage of the intervals is tested statistically
in test_uncertainty.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.uncertainty import Estimate, response_band

GRID = np.arange(999.0)  # exact quantiles (ranks 1000·p): 2.5 % → 24, 97.5 % → 974, 5 % → 49, 95 % → 949


def test_normal_interval_is_value_plus_minus_the_normal_quantile() -> None:
    k = stats.norm.ppf(0.975)
    est = Estimate.normal(10.0, 2.0)
    assert (est.value, est.u) == (10.0, 2.0)
    assert est.interval == (pytest.approx(10.0 - 2.0 * k, abs=1e-12), pytest.approx(10.0 + 2.0 * k, abs=1e-12))


def test_reflected_interval_of_all_draws() -> None:
    """The basic bootstrap interval: (2v − q₉₇.₅, 2v − q₂.₅); u the draws' standard deviation
    (ddof 1; for 0 … N it is √((N + 1)(N + 2)/12))."""
    est = Estimate.of_draws(400.0, GRID)
    assert est.value == 400.0
    assert est.interval == (pytest.approx(800.0 - 974.0), pytest.approx(800.0 - 24.0))
    assert est.u == pytest.approx(math.sqrt(999 * 1000 / 12), rel=1e-12)
    narrow = Estimate.of_draws(400.0, GRID, coverage=0.90)
    assert narrow.interval == (pytest.approx(800.0 - 949.0), pytest.approx(800.0 - 49.0))
    assert Estimate.of_draws(400.0, GRID, reflect=np.ones(999, dtype=bool)) == est


def test_draws_on_another_branch_are_taken_as_they_are() -> None:
    """Unflagged draws enter the quantiles as they are, flagged ones reflected about the value."""
    est = Estimate.of_draws(400.0, GRID, reflect=np.zeros(999, dtype=bool))
    assert est.interval == (pytest.approx(24.0), pytest.approx(974.0))  # the percentile interval
    flags = GRID >= 500  # the upper half reflected about 400: 300 … −198; the lower half kept
    mixed = np.sort(np.where(flags, 800.0 - GRID, GRID))
    est = Estimate.of_draws(400.0, GRID, reflect=flags)
    assert est.interval == (pytest.approx(mixed[24]), pytest.approx(mixed[974]))
    assert est.u == pytest.approx(float(np.std(GRID, ddof=1)))  # u of the draws as drawn


def test_non_finite_draws_are_left_out_with_their_flags() -> None:
    draws = np.concatenate([[np.nan], GRID[:500], [np.inf, -np.inf], GRID[500:]])
    flags = np.concatenate([[True], GRID[:500] >= 500, [False, True], GRID[500:] >= 500])
    assert Estimate.of_draws(400.0, draws, reflect=flags) == Estimate.of_draws(400.0, GRID, reflect=GRID >= 500)
    assert Estimate.of_draws(400.0, np.concatenate([GRID, [np.nan]])) == Estimate.of_draws(400.0, GRID)


@pytest.mark.parametrize("draws", [np.array([]), np.array([3.0]), np.array([3.0, np.nan, np.inf])])
def test_fewer_than_two_finite_draws_give_no_interval(draws: np.ndarray) -> None:
    est = Estimate.of_draws(7.0, draws)
    assert est.value == 7.0 and math.isnan(est.u) and all(math.isnan(x) for x in est.interval)
    # two finite draws are enough: 6 and 8 about 7; the ranks 3·0.025 and 3·0.975 lie beyond the
    # first and the second draw, so the ends are the draws, (14 − 8, 14 − 6), which holds 7
    assert Estimate.of_draws(7.0, np.array([6.0, 8.0])).interval == (pytest.approx(6.0), pytest.approx(8.0))


def test_an_interval_is_extended_to_hold_its_value() -> None:
    """Issue 40 item 3: an interval always contains its own value. Draws 1 and 2 about a value
    of 7 reflect to (14 − 2, 14 − 1) = (12, 13), wholly above 7: the interval is extended to 7 on
    that side and keeps its other end."""
    assert Estimate.of_draws(7.0, np.array([1.0, 2.0])).interval == (7.0, pytest.approx(13.0))
    assert Estimate.of_draws(7.0, np.array([12.0, 13.0])).interval == (pytest.approx(1.0), 7.0)


def test_a_positive_figure_is_reflected_on_a_log_scale() -> None:
    """log draws evenly spaced: the interval is (v²/q₉₇.₅, v²/q₂.₅) and stays above zero, where a
    linear reflection would go below it."""
    draws = 2.0 ** ((GRID - 500.0) / 250.0)  # 1/4 … 2^(498/250)
    v = 1.5
    est = Estimate.of_draws(v, draws, positive=True)
    q_lo, q_hi = 2.0 ** ((24.0 - 500.0) / 250.0), 2.0 ** ((974.0 - 500.0) / 250.0)
    assert est.interval == (pytest.approx(v * v / q_hi, rel=1e-12), pytest.approx(v * v / q_lo, rel=1e-12))
    assert est.u == pytest.approx(float(np.std(draws, ddof=1)), rel=1e-12)
    assert Estimate.of_draws(v, draws).interval[0] < 0 < est.interval[0]
    small = Estimate.of_draws(0.05, 0.05 / 1.5 * draws, positive=True)  # a damping ratio: below 1 too
    assert small.interval == (pytest.approx(est.interval[0] * 0.05 / 1.5, rel=1e-12),
                              pytest.approx(est.interval[1] * 0.05 / 1.5, rel=1e-12))


def test_a_positive_figure_leaves_out_draws_at_or_below_zero() -> None:
    draws = 2.0 ** ((GRID - 500.0) / 250.0)
    with_bad = np.concatenate([draws, [0.0, -1.0]])
    got = Estimate.of_draws(1.5, with_bad, positive=True)
    want = Estimate.of_draws(1.5, draws, positive=True)
    assert got.interval == want.interval and got.u == pytest.approx(want.u, rel=1e-12)
    two = Estimate.of_draws(1.5, np.array([1.0, 2.0, -1.0]), positive=True)
    assert two.u == pytest.approx(math.sqrt(0.5), rel=1e-12)
    one = Estimate.of_draws(1.5, np.array([2.0, -1.0, 0.0]), positive=True)
    assert math.isnan(one.u) and all(math.isnan(x) for x in one.interval)


def test_a_positive_figure_with_flags_and_a_value_not_above_zero() -> None:
    draws = 2.0 ** ((GRID - 500.0) / 250.0)
    flags = GRID >= 500
    logs = np.log(draws)
    mixed = np.sort(np.where(flags, 2 * math.log(1.5) - logs, logs))
    est = Estimate.of_draws(1.5, draws, reflect=flags, positive=True)
    assert est.interval == (pytest.approx(math.exp(mixed[24]), rel=1e-12), pytest.approx(math.exp(mixed[974]), rel=1e-12))
    # a value at zero: the linear reflection (draws about it: −499 … 499 reflect to −475 … 475) ...
    linear = Estimate.of_draws(0.0, GRID - 499.0, positive=True)
    assert linear.interval == (pytest.approx(-475.0), pytest.approx(475.0))
    # ... whose interval, where the draws all lie on one side, is extended to hold the value
    # (issue 40 item 3): 0 … 998 reflect to (−974, −24), held to (−974, 0)
    assert Estimate.of_draws(0.0, GRID, positive=True).interval == (pytest.approx(-974.0), 0.0)
    below = Estimate.of_draws(-100.0, GRID, positive=True)  # and below zero (no log of it): (−1174, −224) → −100
    assert below.interval == (pytest.approx(-1174.0), -100.0)


@pytest.mark.parametrize("v", [1.5, 1.0, 0.5])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_signed_figure_is_its_magnitude_reflected_on_a_log_scale_with_its_sign(sign: float, v: float) -> None:
    """`signed` (a DC gain): the magnitude is treated as `positive`, so the interval is
    sign·(v²/q₉₇.₅, v²/q₂.₅) in order and never crosses zero; u the draws' standard deviation.
    A draw of the other sign has no magnitude of this sign and is left out. A value of 0 has no
    sign: the linear reflection."""
    draws = 1.2 * v * 2.0 ** ((GRID - 500.0) / 250.0)  # 0.3 v … 4.8 v: not symmetric on a log scale about 1
    q_lo, q_hi = 1.2 * v * 2.0 ** ((24.0 - 500.0) / 250.0), 1.2 * v * 2.0 ** ((974.0 - 500.0) / 250.0)
    est = Estimate.of_draws(sign * v, np.concatenate([sign * draws, [-sign * 2.0]]), signed=True)
    ends = sorted((sign * v * v / q_hi, sign * v * v / q_lo))
    assert est.value == sign * v
    assert est.interval == (pytest.approx(ends[0], rel=1e-12), pytest.approx(ends[1], rel=1e-12))
    assert est.interval[0] < est.interval[1] and est.interval[0] * est.interval[1] > 0
    assert est.u == pytest.approx(float(np.std(draws, ddof=1)), rel=1e-12)
    zero = Estimate.of_draws(0.0, sign * (GRID - 499.0), signed=True)
    assert zero.interval == (pytest.approx(-475.0), pytest.approx(475.0))


def test_the_expanded_uncertainty_is_half_the_interval() -> None:
    assert Estimate(1.0, 0.1, (0.8, 1.4)).expanded == pytest.approx(0.3, rel=1e-15)
    assert Estimate(1.0, 0.1).expanded is None
    assert Estimate.normal(10.0, 2.0).expanded == pytest.approx(1.959963984540054 * 2.0, rel=1e-15)


def test_holding_the_value_leaves_an_interval_that_holds_it_or_none() -> None:
    held = Estimate(7.0, 1.0, (6.0, 8.0))
    assert held.holding_value() == held
    assert Estimate(7.0, 1.0, (7.0, 8.0)).holding_value() == Estimate(7.0, 1.0, (7.0, 8.0))
    assert Estimate(7.0, 1.0, (8.0, 9.0)).holding_value() == Estimate(7.0, 1.0, (7.0, 9.0))
    assert Estimate(7.0, 1.0, (5.0, 6.0)).holding_value() == Estimate(7.0, 1.0, (5.0, 7.0))
    assert Estimate(7.0, 1.0).holding_value() == Estimate(7.0, 1.0)
    assert Estimate(None, None, (1.0, 2.0)).holding_value() == Estimate(None, None, (1.0, 2.0))
    # an unbounded end is extended too: "always contains its value" (the docstring of of_draws)
    assert Estimate(7.0, 1.0, (-math.inf, 5.0)).holding_value() == Estimate(7.0, 1.0, (-math.inf, 7.0))
    assert Estimate(7.0, 1.0, (9.0, math.inf)).holding_value() == Estimate(7.0, 1.0, (7.0, math.inf))
    undetermined = Estimate(7.0, math.nan, (math.nan, math.nan)).holding_value()
    assert undetermined.value == 7.0 and all(math.isnan(x) for x in undetermined.interval)

def test_estimate_to_dict_turns_non_finite_numbers_into_none() -> None:
    assert Estimate(1.0, math.nan, (-math.inf, 2.0)).to_dict() == {"value": 1.0, "u": None, "interval": [None, 2.0]}
    assert Estimate(0.0, 0.5, (-1.0, 1.0)).to_dict() == {"value": 0.0, "u": 0.5, "interval": [-1.0, 1.0]}


# -- the response band ------------------------------------------------------------------------------------
DT = 1e-6


def zero_model(c: float, delay: float = 0.0) -> DiscreteModel:
    """B = 1 + c·z⁻¹, A = 1: |H(f)/H(0)| = |1 + c·e^(−jω)|/(1 + c), closed form."""
    return DiscreteModel(DT, np.array([1.0]), np.array([1.0, c]), delay_samples=delay)


def rel_gain(c: float, f: np.ndarray) -> np.ndarray:
    return np.abs(1 + c * np.exp(-2j * np.pi * f * DT)) / (1 + c)


def test_response_band_needs_two_draws_and_a_dc_gain() -> None:
    assert response_band(zero_model(0.2), [zero_model(0.2)], (1e3, 1e5)) is None
    assert response_band(DiscreteModel(DT, np.array([1.0]), np.array([1.0, -1.0])), [zero_model(0.1)] * 2, None) is None


def test_response_band_from_two_draws_and_of_a_negative_dc_gain() -> None:
    """Two draws are enough; a sensor read with inverted polarity (negative DC gain) has the same
    band, each response taken relative to its own DC gain."""
    assert response_band(zero_model(0.2), [zero_model(0.1), zero_model(0.3)], (1e3, 1e5), points=5) is not None
    cs = GRID / 2000.0

    def inverted(c: float) -> DiscreteModel:
        return DiscreteModel(DT, np.array([1.0]), np.array([-1.0, -c]))

    want = response_band(zero_model(0.25), [zero_model(c) for c in cs], (1e3, 1e5), points=10)
    got = response_band(inverted(0.25), [inverted(c) for c in cs], (1e3, 1e5), points=10)
    for key in ("magnitude_rel", "magnitude_rel_low", "magnitude_rel_high", "phase_low_deg", "phase_high_deg"):
        np.testing.assert_allclose(got[key], want[key], rtol=1e-12, atol=1e-9)


def test_response_band_grid() -> None:
    band = response_band(zero_model(0.2), [zero_model(0.2)] * 3, (1e3, 1e5), points=50)
    np.testing.assert_allclose(band["frequency_hz"], np.geomspace(1e3, 2e5, 50), rtol=1e-12)
    assert band["coverage_probability"] == 0.95
    band = response_band(zero_model(0.2), [zero_model(0.2)] * 3, (10.0, 4e5), points=20)  # at most 0.98 Nyquist
    np.testing.assert_allclose(band["frequency_hz"], np.geomspace(100.0, 0.98 * 5e5, 20), rtol=1e-12)
    band = response_band(zero_model(0.2), [zero_model(0.2)] * 3, None, points=20)  # no band: to Nyquist / 2
    np.testing.assert_allclose(band["frequency_hz"], np.geomspace(100.0, 2.5e5, 20), rtol=1e-12)
    band = response_band(zero_model(0.2), [zero_model(0.2)] * 3, (0.0, 1e5), points=20)
    assert band["frequency_hz"][0] == pytest.approx(100.0)


def test_response_band_magnitude_reflected_on_a_log_scale() -> None:
    """Draws 1 + c·z⁻¹, c = 0 … 0.499 evenly (999), about the model c₀ = 0.25: at each frequency the
    DC-relative gain falls as c grows, so its quantiles are those of c: the 2.5 % point is c = 0.012
    and the band (reflected about the model on a log scale) is g₀²/g(c) at the two ends."""
    cs = GRID / 2000.0
    band = response_band(zero_model(0.25), [zero_model(c) for c in cs], (1e3, 1e5), points=30)
    f = np.asarray(band["frequency_hz"])
    g0 = rel_gain(0.25, f)
    np.testing.assert_allclose(band["magnitude_rel"], g0, rtol=1e-12)
    np.testing.assert_allclose(band["magnitude_rel_low"], g0**2 / rel_gain(cs[24], f), rtol=1e-9)
    np.testing.assert_allclose(band["magnitude_rel_high"], g0**2 / rel_gain(cs[974], f), rtol=1e-9)
    unreflected = response_band(zero_model(0.25), [zero_model(c) for c in cs], (1e3, 1e5),
                                reflect=np.zeros(cs.size, dtype=bool), points=30)
    np.testing.assert_allclose(unreflected["magnitude_rel_low"], rel_gain(cs[974], f), rtol=1e-9)
    np.testing.assert_allclose(unreflected["magnitude_rel_high"], rel_gain(cs[24], f), rtol=1e-9)


def test_response_band_phase_with_the_delay() -> None:
    """Pure delays d + δ, δ = 0 … 0.998 sample (999): the phase is −360°·f·T·d (unwrapped); the
    reflected band is the phase + 360°·f·T·(δ₂.₅, δ₉₇.₅) = (0.024, 0.974); taken as they are,
    − 360°·f·T·(δ₉₇.₅, δ₂.₅)."""
    d = 3.3
    deltas = GRID / 1000.0
    draws = [DiscreteModel(DT, np.array([1.0]), np.array([1.0]), delay_samples=d + x) for x in deltas]
    model = DiscreteModel(DT, np.array([1.0]), np.array([1.0]), delay_samples=d)
    band = response_band(model, draws, (1e3, 1e5), points=25)
    f = np.asarray(band["frequency_hz"])
    turn = 360.0 * f * DT
    np.testing.assert_allclose(band["phase_deg"], -turn * d, rtol=1e-9)
    np.testing.assert_allclose(band["phase_low_deg"], -turn * d + turn * 0.024, rtol=1e-9)
    np.testing.assert_allclose(band["phase_high_deg"], -turn * d + turn * 0.974, rtol=1e-9)
    np.testing.assert_allclose(band["magnitude_rel_low"], 1.0, rtol=1e-12)
    taken = response_band(model, draws, (1e3, 1e5), reflect=np.zeros(deltas.size, dtype=bool), points=25)
    np.testing.assert_allclose(taken["phase_low_deg"], -turn * d - turn * 0.974, rtol=1e-9)
    np.testing.assert_allclose(taken["phase_high_deg"], -turn * d - turn * 0.024, rtol=1e-9)


def test_response_band_leaves_out_draws_without_a_dc_gain_with_their_flags() -> None:
    cs = GRID / 2000.0
    flags = GRID >= 500
    dead = DiscreteModel(DT, np.array([1.0]), np.array([1.0, -1.0]))
    base = response_band(zero_model(0.25), [zero_model(c) for c in cs], (1e3, 1e5), reflect=flags, points=10)
    padded = response_band(zero_model(0.25), [dead, *(zero_model(c) for c in cs), dead], (1e3, 1e5),
                           reflect=np.concatenate([[False], flags, [True]]), points=10)
    assert padded == base


def test_response_band_adds_each_type_b_rows_widest_variant_times_a_uniform_factor() -> None:
    """Draws all equal to the model (no Monte Carlo spread), one Type B row: every draw departs
    from the nominal by ξ·log|r| in magnitude and ξ·∠r in phase, r the row's widest variant's
    response over the nominal's (c = 0.3 departs further from c₀ = 0.25 than c = 0.26 at every
    frequency) and ξ ~ U(−1, 1), whose 2.5 % and 97.5 % points are ∓0.95. With 4 001 draws the
    sample quantile's standard error is √(0.975·0.025/4001)/0.5 = 0.005: ±0.02 is 4 of them. A row
    whose variants have no DC gain adds nothing, and the rows' departures add."""
    n = 4001
    model = zero_model(0.25)
    nominal_only = response_band(model, [model] * n, (1e3, 1e5), points=12)
    assert nominal_only["magnitude_rel_low"] == nominal_only["magnitude_rel"]
    dead = DiscreteModel(DT, np.array([1.0]), np.array([1.0, -1.0]))
    assert response_band(model, [model] * n, (1e3, 1e5), points=12, systematic=[(dead,)]) == nominal_only
    band = response_band(model, [model] * n, (1e3, 1e5), points=12,
                         systematic=[(dead,), (zero_model(0.26), zero_model(0.3))])
    f = np.asarray(band["frequency_hz"])
    g0 = rel_gain(0.25, f)
    r = (1 + 0.3 * np.exp(-2j * np.pi * f * DT)) / (1 + 0.3) / ((1 + 0.25 * np.exp(-2j * np.pi * f * DT)) / 1.25)
    log_r, turn = np.abs(np.log(np.abs(r))), np.abs(np.degrees(np.angle(r)))
    np.testing.assert_allclose(band["magnitude_rel"], g0, rtol=1e-12)
    for key, sign in (("magnitude_rel_low", -1.0), ("magnitude_rel_high", 1.0)):
        factor = np.log(np.asarray(band[key]) / g0) / log_r  # ±0.95
        np.testing.assert_allclose(factor, sign * 0.95, atol=0.02)
    phase = np.asarray(band["phase_deg"])
    for key, sign in (("phase_low_deg", -1.0), ("phase_high_deg", 1.0)):
        np.testing.assert_allclose((np.asarray(band[key]) - phase) / turn, sign * 0.95, atol=0.02)
    # two rows of the same variant: ξ₁ + ξ₂ has a triangular PDF on (−2, 2), whose 97.5 % point is
    # 2 − 2√0.05 = 1.553 (the standard error: √(0.975·0.025/4001)/(√0.05/2) = 0.022; ±0.09 is 4 of them)
    twice = response_band(model, [model] * n, (1e3, 1e5), points=12,
                          systematic=[(zero_model(0.3),), (zero_model(0.3),)])
    factor = np.log(np.asarray(twice["magnitude_rel_high"]) / g0) / log_r
    np.testing.assert_allclose(factor, 2 - 2 * math.sqrt(0.05), atol=0.09)
    # a sensor read with inverted polarity: its variants too have a negative DC gain, and each
    # response is taken relative to its own, so the band is the same
    def inverted(c: float) -> DiscreteModel:
        return DiscreteModel(DT, np.array([1.0]), np.array([-1.0, -c]))

    flipped = response_band(inverted(0.25), [inverted(0.25)] * n, (1e3, 1e5), points=12,
                            systematic=[(dead,), (inverted(0.26), inverted(0.3))])
    for key in ("magnitude_rel_low", "magnitude_rel_high", "phase_low_deg", "phase_high_deg"):
        np.testing.assert_allclose(flipped[key], band[key], rtol=1e-12, atol=1e-9)
    # a row drawn at a share s of its variant's departure (systematics.evidence_scale): ξ·s, whose
    # 97.5 % point is 0.95·s
    shared = response_band(model, [model] * n, (1e3, 1e5), points=12, systematic=[(zero_model(0.3),)],
                           systematic_scales=[0.4])
    factor = np.log(np.asarray(shared["magnitude_rel_high"]) / g0) / log_r
    np.testing.assert_allclose(factor, 0.95 * 0.4, atol=0.01)


def test_a_positive_figure_whose_reflected_end_passes_the_largest_float_is_unbounded_not_an_error() -> None:
    """Reflected on a log scale, value²/draw: a value of 1e300 with draws down to 1e290 puts the
    upper end at 1e310, beyond the largest float; math.exp raised OverflowError (a traceback)."""
    draws = np.geomspace(1e290, 1e300, 50)
    est = Estimate.of_draws(1e300, draws, positive=True)
    assert est.interval is not None and est.interval[1] == math.inf
    assert est.interval[0] <= 1e300 <= est.interval[1]


def test_a_richer_models_bound_is_its_akaike_weights_share_and_never_above_the_rectangle() -> None:
    """systematics.akaike_weight and evidence_scale: the nested richer model's shift Δ enters the
    budget with u = √w·|Δ| (the model-averaged variance about the chosen model's value, Burnham and
    Anderson 2002), w = 1/(1 + exp(ΔV/ĉ + Δk)), ĉ = max(1, V/half_dof); as a rectangle's
    half-width factor √(3w), at most 1 (the whole rectangle, u = |Δ|/√3, where the evidence favours
    the richer model)."""
    from types import SimpleNamespace

    from hopkinson.analysis.systematics import TypeB, akaike_weight, evidence_scale

    def weight(v_nominal: float, dv: float, dk: int, half_dof: float = 1000.0) -> float:
        richer = SimpleNamespace(cost=v_nominal + dv, parameters=10 + dk)
        return akaike_weight(richer, SimpleNamespace(cost=v_nominal, parameters=10), half_dof)

    w = 1.0 / (1.0 + math.exp(3.0 + 4.0))  # worse by 3 for 4 more parameters, no over-dispersion
    assert weight(100.0, 3.0, 4) == pytest.approx(w, rel=1e-12)
    assert evidence_scale(w) == pytest.approx(math.sqrt(3 * w), rel=1e-12)
    row = TypeB("richer", {"dc_gain": 0.01 * evidence_scale(w)})
    assert row.u_rel_by_figure({"dc_gain": 1.0})["dc_gain"] == pytest.approx(math.sqrt(w) * 0.01, rel=1e-12)
    # over-dispersed (V three times its expectation): ΔV counts a third
    assert weight(300.0, 6.0, 4, half_dof=100.0) == pytest.approx(1.0 / (1.0 + math.exp(6.0 / 3.0 + 4.0)), rel=1e-12)
    # better by 4 for 6 more parameters: still disfavoured (w = 0.12)
    assert weight(100.0, -4.0, 6) == pytest.approx(1.0 / (1.0 + math.e ** 2), rel=1e-12)
    # favoured (w ≥ 1/3): the whole rectangle, never more
    assert weight(100.0, -20.0, 4) > 0.99
    assert evidence_scale(weight(100.0, -20.0, 4)) == 1.0
    assert evidence_scale(weight(100.0, math.log(2.0) - 4.0, 4)) == pytest.approx(1.0, rel=1e-12)
    # far worse: no overflow, a vanishing share
    assert 0.0 <= weight(100.0, 5000.0, 4) < 1e-200
