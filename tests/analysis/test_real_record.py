"""Issue 10's real record, rehearsed on a simulated truth: a piezoelectric reference
accelerometer (main mode 51.4 kHz, ζ = 0.03, a second mode at 140 kHz beyond the excitation)
on a 10 MS/s record of a bipolar pulse that leaves the resonance nearly unexcited, a
differentiated-interferometer reference, a fractional skew and a response that drifts (a
charge amplifier's drift, a zero shift after the shock). Truth: the continuous model."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from scipy import signal

from hopkinson.analysis.frequency_fit import OrderProblem
from hopkinson.analysis.identify import Identification, identify
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.order_choice import choose_stable_order
from hopkinson.analysis.records import Record
from hopkinson.analysis.response import fbsd_hz
from hopkinson.analysis.sine_comparison import SineCalibration, compare_sine
from hopkinson.analysis.uncertainty import evaluate
from hopkinson.drivers.sim.accelerometer import (
    AccelerometerTruth,
    Mode,
    baseline_drift,
    fractional_delay,
)
from hopkinson.drivers.sim.doppler_beat import interferometer_noise_m_s2
from hopkinson.drivers.sim.shock import bipolar_m_s2
from tests.analysis.hard_records import DT, Case, record, truth_figures

PIEZO = Case(
    truth=AccelerometerTruth(modes=(Mode(51_400.0, 0.03), Mode(140_000.0, 0.05)), sensitivity=1e-4),
    width_s=40e-6, bipolar_ratio=0.55, samples=20_000, start_s=300e-6,
    reference_noise=0.003, interferometer_noise=0.012, interferometer_band_hz=2e6, response_noise=0.004,
    skew_samples=0.04, drift_per_s=30.0,
)


# Two tests each read the identification of record(PIEZO, 2) and of pulse_a(101): identify is
# deterministic, so each record is identified once for the module.
@cache
def piezo_identified(seed: int) -> Identification:
    return identify(record(PIEZO, seed))


@cache
def pulse_a_identified(seed: int) -> Identification:
    return identify(pulse_a(seed))


@pytest.mark.parametrize("seed", [1, 2])
def test_a_drifting_response_is_detrended_not_fitted_with_spare_low_frequency_poles(seed: int) -> None:
    # The drift (6 % of the peak by the record's end) kept the response 'loud' against its
    # pre-pulse level to the end: the record was taken as cut short, the drift stayed in, and
    # the fit chased it with a real pole near DC (a negative DC gain, FBSD at 1 Hz) or a 'main
    # mode' at a few hundred hertz.
    truth = truth_figures(PIEZO)
    ident = piezo_identified(seed)
    assert not any("record ends before" in w for w in ident.warnings)
    assert ident.preprocessing.response_drift.slope_per_s != 0.0
    assert all(m["natural_frequency_hz"] > 20_000.0 for m in ident.modes)
    # The pulse leaves the resonance nearly unexcited: claimed only as what it is, or flagged.
    main = ident.main_mode
    assert main is None or main["natural_frequency_hz"] == pytest.approx(truth["natural_frequency_hz"], rel=5e-3)
    assert main is not None or any(not m["supported"] and abs(m["natural_frequency_hz"] / 51_400.0 - 1) < 0.05
                                   for m in ident.modes)
    assert ident.model.dc_gain == pytest.approx(truth["dc_gain"], rel=5e-3)
    edges = fbsd_hz(ident.model)
    assert edges["5"] == pytest.approx(truth["fbsd_5"], rel=0.03)
    assert edges["10"] == pytest.approx(truth["fbsd_10"], rel=0.03)


@pytest.mark.parametrize("seed", [6, 8])
def test_a_slow_baseline_wander_is_weighed_as_noise_not_fitted_as_a_mode(seed: int) -> None:
    # A baseline that wanders slowly (0.1 % of the peak, below 300 Hz: cable, thermal) puts
    # noise in the lowest fitted bins that the fit's noise look (segments detrended) did not
    # see: a spare pole at ~500 Hz beat the true order, DC gain −5 … −6 %, FBSD ±5 % at 1 kHz.
    truth = truth_figures(PIEZO)
    rec = record(PIEZO, seed)
    peak = float(np.max(np.abs(rec.response)))
    wander = baseline_drift(rec.response.size, DT, 0.0, wander_rms=1e-3 * peak, wander_hz=300.0,
                            rng=np.random.default_rng(seed + 1000))
    ident = identify(Record(DT, rec.reference, rec.response + wander))
    assert all(m["natural_frequency_hz"] > 20_000.0 for m in ident.modes)
    assert ident.model.dc_gain == pytest.approx(truth["dc_gain"], rel=5e-3)
    assert fbsd_hz(ident.model)["5"] == pytest.approx(truth["fbsd_5"], rel=0.03)


@pytest.mark.parametrize(("skew_samples", "leads"), [(-6.0, True), (-3.0, True), (-1.0, True), (0.04, False)])
def test_a_response_leading_the_reference_is_reported_even_where_the_zeros_absorb_it(
        skew_samples: float, leads: bool) -> None:
    # The delay and the zeros share a flat valley of the cost: B's zeros took up a 3-sample lead
    # as a phase advance, the fitted delay stayed ≥ 0 (0 … 0.8), the free-delay refit gained
    # nothing, and no warning was given. The model's whole group delay at low frequencies is
    # what the lead moves: the truth's (sensor lag ~0.3 samples) plus the skew. Since stop 38 a
    # lead beyond 2 samples by the channels' cross-correlation (here −3 and −6) is realigned
    # before the fit and kept in the model's delay, which goes negative where the zeros do not
    # take it all.
    from hopkinson.analysis.group_delay import model_dc_group_delay_samples

    ident = identify(record(PIEZO.scaled(skew_samples=skew_samples), 1))
    said = [w for w in ident.warnings if "leads the reference" in w]
    assert bool(said) == leads, ident.warnings
    whole = ident.delay_samples + model_dc_group_delay_samples(ident.model)
    assert whole == pytest.approx(skew_samples + 0.3, abs=0.3)
    assert ("realigned" in " ".join(said)) == (skew_samples < -2.0)
    if leads:
        lead = float(said[0].split("by about ")[1].split(" samples")[0])
        assert lead == pytest.approx(-skew_samples - 0.3, abs=0.3)


def test_an_order_unstable_when_converged_is_replaced_by_the_tests_choice_not_the_lowest_cost() -> None:
    # Orders 3 and 4 both beat order 2 in the search; order 4 turns out unstable once converged.
    # Order 3 must then be weighed by the test against order 2 (it barely gains: order 2), not
    # taken for having the lowest cost of the stable orders.
    costs = {1: 5000.0, 2: 100.0, 3: 99.9, 4: 40.0}
    parameters = {n: 3 * n + 3 for n in costs}
    change = {(n, m): 0.05 for n in costs for m in costs if m > n}
    chosen, dropped = choose_stable_order(costs, parameters, 116, change, lambda n: n != 4)
    assert (chosen, dropped) == (2, [4])
    chosen, dropped = choose_stable_order(costs, parameters, 116, change, lambda n: n not in (2, 4))
    assert (chosen, dropped) == (3, [4, 2])
    assert choose_stable_order(costs, parameters, 116, change, lambda n: False)[0] is None


def pulse_a(seed: int) -> Record:
    """The rehearsal's sharp pulse "A" exactly as it was recorded (issue 10): the piezo reference
    at 10 MS/s, an 85 km/s² bipolar pulse (40 µs, then 50 µs at 0.55) that excites the
    resonance, interferometer and digitizer noise on the reference, white noise on the
    response, a 0.04 µs skew (the noise skewed with it), a drift with a slow wander and an
    offset."""
    rng = np.random.default_rng(seed)
    t = np.arange(PIEZO.samples) * DT
    peak = 85e3
    u0 = bipolar_m_s2(t, 40e-6, peak, 300e-6, ratio=0.55, second_width_s=50e-6)
    y0 = PIEZO.truth.respond(u0, DT)
    u = u0 + interferometer_noise_m_s2(t.size, DT, 0.012 * peak, 2e6, rng) + 0.003 * peak * rng.standard_normal(t.size)
    peak_y = float(np.max(np.abs(y0)))
    y = fractional_delay(y0 + 0.004 * peak_y * rng.standard_normal(t.size), 0.4)
    y = y + baseline_drift(t.size, DT, 10.0 * peak_y, wander_rms=1e-3 * peak_y, wander_hz=300.0, rng=rng) + 0.002
    return Record(DT, u, y)


@pytest.mark.parametrize("seed", [113, 101])
def test_the_delay_branch_the_noise_flips_is_inside_the_fbsd_interval(seed: int) -> None:
    # The delay and B's zeros share a flat valley of the cost with two optima (τ ≈ 0.4 and
    # ≈ 3.1 samples at 1 MS/s, costs within chance); the noise picks one, and the FBSD moves
    # with it by ~1 % (−0.6 % on the first, +0.2 … +0.7 % on the second). The draws stayed on
    # the nominal branch, so the 95 % interval held only one branch's scatter and missed the
    # truth (seed 113 on the first branch, 101 on the second; 15/20 seeds covered).
    truth = truth_figures(PIEZO)
    ident = pulse_a_identified(seed)
    result = evaluate(ident, AnalysisOptions(draws=200, seed=3))
    for key in ("5", "10"):
        lo, hi = result.fbsd_hz[key].interval
        assert lo <= truth[f"fbsd_{key}"] <= hi, (key, lo, hi, truth[f"fbsd_{key}"])
    # Where the two optima of the cost (found here by starting the fit on either side of the
    # valley) are within chance of each other, the reported delay's interval spans both, not only
    # the branch the record happened to take. (Since issue 40 the band runs across the pulse's
    # nulls, to 84 kHz: on seed 101 its bins tell the branches apart, V 84.4 against 91.4, and the
    # draws stay on the better one; on seed 113 they stay within chance, 50.5 against 50.7.)
    fitted = ident.settlement
    problem = OrderProblem(fitted.data, ident.order, "causal", fitted.setup.max_delay)
    fits = [problem.solve(problem.linear_start(tau), 200, 1e-10) for tau in (0.0, 4.0)]
    optima = [f.delay for f in fits]
    assert abs(optima[1] - optima[0]) > 2.0
    lo, hi = (x / ident.sample_interval_s for x in result.delay_s.interval)
    if abs(fits[1].cost - fits[0].cost) <= 2.0:  # within chance (V is half a χ²: ΔV 2 is p ≈ 0.05)
        assert lo <= min(optima) + 0.1 and hi >= max(optima) - 0.1, (lo, hi, optima)
    else:
        assert seed == 101
        best = min(fits, key=lambda f: f.cost).delay
        assert lo <= best <= hi, (lo, hi, best)


def test_compare_sine_judges_the_models_whole_phase_not_the_part_left_by_an_undetermined_delay() -> None:
    # On the record whose fit took the 3-sample branch, the model's phase without its fitted
    # delay was 22.6° off the sensor's at 20 kHz ('a delay of −3.1 µs'). The truth of the
    # record: the simulator's sensor (its zero-order-hold filter at 10 MS/s, which lags the
    # continuous sensor by a sample) behind the 0.04 µs skew; a sine calibration of that
    # sensor and channel is what the model's whole phase must match.
    ident = pulse_a_identified(101)
    assert ident.delay_samples > 2.0  # the branch the bug showed on
    f = np.array([500.0, 1e3, 2e3, 4e3, 6.3e3, 8e3, 10e3, 12.5e3, 16e3, 20e3])
    _, h = signal.sosfreqz(PIEZO.truth.sections(DT, "zoh"), worN=f, fs=1.0 / DT)
    h = h * np.exp(-2j * np.pi * f * 0.4 * DT)
    c = compare_sine(ident.model, SineCalibration(f, np.abs(h), np.degrees(np.angle(h))))
    assert np.max(np.abs(c.phase_error_deg)) < 0.3
    assert abs(c.phase_delay_s) < 0.03e-6
    assert c.fitted_delay_s == pytest.approx(ident.delay_samples * 1e-6)


def test_each_delay_branch_is_a_distinct_optimum_of_the_cost() -> None:
    # A branch found a sample away and iterated to convergence slid back onto the fit's own
    # optimum (the valley is flat): a duplicate at the same delay and cost, whose draws the
    # interval then took unreflected as another branch's.
    ident = piezo_identified(2)
    fitted = ident.settlement
    fit = fitted.sweep.fits[ident.order]
    for branch in fitted.branches.get(ident.order, []):
        assert abs(branch.delay - fit.delay) >= 1.0, (branch.delay, fit.delay)
        assert branch.cost >= fit.cost
