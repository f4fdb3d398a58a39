"""One model from a shock record and a sine calibration (analysis.sine_joint, issue 17 item 4),
against a simulated sensor with a known truth and sine calibrations drawn from it (or from
another sensor) with known noise."""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache

import numpy as np
import pytest

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.frequency_fit import OrderProblem
from hopkinson.analysis.identify import identify_with_sine
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.sine_comparison import SineCalibration
from hopkinson.analysis.sine_joint import JointWeights, paule_mandel, sine_terms, with_draws
from hopkinson.analysis.uncertainty import evaluate
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from tests.analysis.hard_records import Case, record, truth_figures
from tests.analysis.numeric_jacobian import central_differences

CASE = Case()  # 27 kHz, ζ 0.05, a 20 µs half-sine: the mode inside the supported band
OTHER = AccelerometerTruth(modes=(Mode(40_000.0, 0.05),), sensitivity=CASE.truth.sensitivity)
FREQUENCY_HZ = np.arange(500.0, 20_001.0, 500.0)
U_MAG_REL, U_PHASE_DEG = 0.003, 0.3


def synthetic_sine(truth: AccelerometerTruth, seed: int) -> SineCalibration:
    """A sine calibration of `truth` with Gaussian errors of exactly the stated u."""
    rng = np.random.default_rng([seed, 17])
    h = truth.frequency_response(FREQUENCY_HZ)
    n = FREQUENCY_HZ.size
    return SineCalibration(FREQUENCY_HZ, np.abs(h) * (1 + U_MAG_REL * rng.standard_normal(n)),
                           np.degrees(np.angle(h)) + U_PHASE_DEG * rng.standard_normal(n),
                           np.full(n, U_MAG_REL), np.full(n, U_PHASE_DEG), "synthetic")


@cache
def same_sensor_joint():
    """The joint identification of seed 3's record and a sine calibration of the same sensor
    (deterministic: identified once for the module's tests that read it)."""
    return identify_with_sine(record(CASE, 3), synthetic_sine(CASE.truth, 3))


@pytest.fixture(scope="module")
def joint():
    """The joint identification of one seed, with its Monte Carlo (shared by the assertions)."""
    ident = same_sensor_joint()
    result = evaluate(ident, AnalysisOptions(draws=100, seed=5, order_draws=10))
    return with_draws(ident, result.model_draws), result


def test_the_joint_figures_contain_the_truth(joint) -> None:
    """One seed (a 95 % interval misses on 1 seed in 20; this seed is not chosen to pass: seed 3
    as elsewhere). The coverage over 40 seeds is benchmarks/bench_sine_joint_coverage.py's
    (joint: 95–100 % per figure; README)."""
    ident, result = joint
    truth = truth_figures(CASE)
    for name, estimate in (("fbsd_5", result.fbsd_hz["5"]), ("fbsd_10", result.fbsd_hz["10"]),
                           ("natural_frequency_hz", result.natural_frequency_hz),
                           ("damping_ratio", result.damping_ratio), ("dc_gain", result.dc_gain)):
        lo, hi = estimate.interval
        assert lo <= truth[name] <= hi, (name, estimate, truth[name])
    budget = {b["source"]: b["u_rel_by_figure"] for b in result.budget}
    assert budget["sine calibration"]["fbsd_5_hz"] > 0  # the sine points' own uncertainty is carried


def test_a_sine_of_the_same_sensor_is_consistent(joint) -> None:
    ident, _ = joint
    report = ident.to_dict()["sine_joint"]
    assert report["consistent"] is True and report["verdict"].startswith("consistent")
    assert len(report["e_n"]) == FREQUENCY_HZ.size and report["model_draws"] > 50
    # the same units: the sine's level ÷ the shock's is 1 within its uncertainty
    assert abs(report["gain_ratio"] - 1.0) < 2.0 * math.hypot(report["gain_ratio_u"], U_MAG_REL)
    assert report["gain_ratio_e_n"] < 1.0
    assert report["scatter_magnitude_rel"] < U_MAG_REL  # no extra scatter needed (Paule–Mandel)


def test_a_sine_of_another_sensor_is_flagged_inconsistent() -> None:
    ident = identify_with_sine(record(CASE, 3), synthetic_sine(OTHER, 3))
    report = ident.to_dict()["sine_joint"]
    assert report["consistent"] is False and report["verdict"].startswith("inconsistent")
    e_n = np.array(report["e_n"])
    assert np.all(e_n[FREQUENCY_HZ >= 5e3] > 1.0)  # 27 vs 40 kHz: > 1.4 % apart from 5 kHz up
    # the shock still decides the mode: the other sensor's sine is weighed by its scatter
    assert abs(ident.main_mode["natural_frequency_hz"] - 27e3) < 0.01 * 27e3
    assert report["scatter_magnitude_rel"] > 0.05


def test_the_verdict_holds_its_false_alarm_rate_over_seeds() -> None:
    """The χ² verdict at 95 % on sine calibrations drawn from the truth: 8 seeds (without the
    model's uncertainty, which only lowers χ²), a false alarm in ≤ 2 of 8. A verdict that flagged
    half the seeds fails with probability 0.96; a correct one passes with 0.994."""
    flagged = 0
    for seed in range(8):
        ident = identify_with_sine(record(CASE, 100 + seed), synthetic_sine(CASE.truth, 100 + seed))
        flagged += not ident.sine_joint.consistent
    assert flagged <= 2


def test_the_sine_rows_jacobian_matches_the_residual() -> None:
    ident = same_sensor_joint()
    fitted = ident.settlement
    problem = OrderProblem(fitted.data, ident.order, fitted.sweep.delay_mode, fitted.setup.max_delay)
    theta = problem.pack(fitted.sweep.fits[ident.order]) * (1 + 1e-4)
    jac = problem.jacobian(theta)
    numeric = central_differences(problem.residual, theta, 1e-7)
    rows = 2 * FREQUENCY_HZ.size
    np.testing.assert_allclose(jac[-rows:], numeric[-rows:], rtol=1e-5, atol=1e-6 * np.max(np.abs(numeric)))


def test_paule_mandel_equal_uncertainties_closed_form() -> None:
    rng = np.random.default_rng(4)
    r = 0.02 * rng.standard_normal(30)
    u = np.full(30, 0.005)
    s = paule_mandel(r, u, 29)
    assert s == pytest.approx(math.sqrt(float(np.sum(r ** 2)) / 29 - 0.005 ** 2), rel=1e-4)
    assert paule_mandel(0.001 * r, u, 29) == 0.0


def test_sine_points_beyond_the_analysis_nyquist_are_refused() -> None:
    sine = synthetic_sine(CASE.truth, 1)
    far = replace(sine, frequency_hz=sine.frequency_hz * 40)  # up to 800 kHz at 1 MS/s
    with pytest.raises(AnalysisError, match="Nyquist"):
        identify_with_sine(record(CASE, 3), far)
    assert sine_terms(sine, 1e-6, JointWeights(4.0, 0.0, 0.0)).weight == 2.0
