"""Issue 40 item 3: no impossible claims. An interval contains its own value and stays inside its
figure's physical bounds; a figure the shot does not determine reads "not determined" with the
reason (a typed result, never a number with an absurd interval); a shot whose DC gain is not
determined is no result; the ISO 16063-13 peak ratio S_sh is given only where the standard's
condition holds (item 5); a heavily damped pole pair is no resonance."""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.analysis.determination import SHOCK_OVERSHOOT_LIMIT, is_result, not_determined
from hopkinson.analysis.estimate import Estimate
from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.analysis.modes import claimed, main_mode, modes_of


def test_an_interval_always_holds_its_value() -> None:
    """Draws that lie all on one side of the estimate (they do not bracket it) once gave intervals
    that excluded their own value (FBSD ±5 % 307 Hz in [4.6 kHz, 3.2 MHz]); the interval now
    reaches the value."""
    rng = np.random.default_rng(1)
    for value, draws in ((307.0, 4.6e3 + rng.random(200) * 3e6), (1.25, 0.3 + 0.01 * rng.standard_normal(200))):
        for positive in (False, True):
            e = Estimate.of_draws(value, draws, positive=positive)
            assert e.interval[0] <= value <= e.interval[1], (value, positive, e)


def test_a_dc_gain_interval_never_crosses_zero() -> None:
    """A DC gain of 1.25 read [−728, 0.295] (issue 40): its magnitude is reflected on a log scale,
    so the interval keeps the value's sign, for either sign."""
    rng = np.random.default_rng(2)
    draws = 1.25 + rng.standard_normal(400) * 2.0  # draws that reach far past zero
    for sign in (1.0, -1.0):
        e = Estimate.of_draws(sign * 1.25, sign * draws, signed=True)
        lo, hi = e.interval
        assert lo <= sign * 1.25 <= hi and lo * hi > 0, e


def _results(**changes) -> dict:
    """A minimal results dict (ShotAnalysis.to_dict's shape) of a determined shot."""
    base = {
        "identification": {"main_mode": {"natural_frequency_hz": 29_700.0, "damping_ratio": 0.05}, "modes": []},
        "model": {"dc_gain": 1.0},
        "uncertainty": {"dc_gain": {"value": 1.0, "u": 0.003, "interval": [0.994, 1.006]},
                        "main_mode": {"natural_frequency_hz": {"value": 29_700.0, "u": 5.0,
                                                               "interval": [29_690.0, 29_710.0]},
                                      "damping_ratio": {"value": 0.05, "u": 1e-4, "interval": [0.0498, 0.0502]}},
                        "fbsd_hz": {"5": {"value": 6_500.0, "u": 10.0, "interval": [6_480.0, 6_520.0]}}},
        "reduction": {"shock_sensitivity": 1.0},
        "peak_overshoot": 1.0,
        "fbsd_bounds": {},
    }
    for key, value in changes.items():
        base[key] = value
    return base


def test_a_determined_shot_reads_every_figure() -> None:
    results = _results()
    found = not_determined(results)
    assert found == {} and is_result(found) == (True, "")


def test_an_absurdly_wide_interval_is_not_a_determination_and_the_shot_is_no_result() -> None:
    """Projectile No. 3 at 1 bar once read a DC gain of 72.8 ± 5 000 with FBSD ±5 % of 0.3 Hz: the
    DC gain is not determined, so the shot is no result, and says why."""
    results = _results()
    results["uncertainty"]["dc_gain"] = {"value": 72.8, "u": 2500.0, "interval": [0.01, 5000.0]}
    found = not_determined(results)
    assert "does not determine" in found["dc_gain"] and "72.8" in found["dc_gain"]
    valid, why = is_result(found)
    assert not valid and "no result" in why
    results["not_determined"], results["result"] = found, {"valid": valid, "reason": why}
    kf = KeyFigures.from_results(results)
    assert not kf.is_result and kf.sensitivity.value is None and kf.sensitivity.not_determined
    assert kf.sensitivity.format().startswith("not determined")


def test_no_resonance_claimed_reads_not_determined_with_why() -> None:
    results = _results(identification={"main_mode": None, "resonance_above_hz": 20_100.0, "modes": []})
    found = not_determined(results)
    assert "above 20.1 kHz" in found["natural_frequency_hz"] and found["damping_ratio"] == found["natural_frequency_hz"]


@pytest.mark.parametrize("overshoot, valid", [(1.0, True), (1 + 0.5 * SHOCK_OVERSHOOT_LIMIT, True), (1.53, False)])
def test_the_peak_ratio_is_the_sensitivity_only_where_iso_16063_13_s_condition_holds(overshoot, valid) -> None:
    """A pulse that rings the resonance inflates the peak ratio (1.53 × the DC gain on the
    simulator's bonded bar): S_sh is then "not the sensitivity for this pulse", with the reason,
    and KeyFigures gives none (the campaign's linearity and the sensor's history then do not read
    it as a sensitivity that drifted)."""
    results = _results(peak_overshoot=overshoot)
    found = not_determined(results)
    assert ("shock_sensitivity" not in found) == valid
    if not valid:
        assert found["shock_sensitivity"].startswith("not the sensitivity for this pulse") and "1.530" in found[
            "shock_sensitivity"]
        results["not_determined"] = found
        kf = KeyFigures.from_results(results)
        assert kf.shock_sensitivity is None and "shock_sensitivity" in kf.not_determined


def test_a_heavily_damped_pole_pair_is_no_resonance() -> None:
    """Shots claimed modes at 55–66 kHz with ζ 0.43–0.58 and one at 18.5 kHz with ζ 0.75: a pole
    pair damped more than 0.3 shapes the response but is never claimed, nor the main mode."""
    dt = 1e-6

    def pair(f_hz: float, zeta: float) -> list[complex]:
        s = 2 * np.pi * f_hz * (-zeta + 1j * np.sqrt(1 - zeta**2))
        return [np.exp(s * dt), np.exp(np.conj(s) * dt)]

    modes = modes_of(np.array(pair(18_500, 0.75) + pair(29_700, 0.05) + pair(60_000, 0.5)), dt, (0.0, 100e3))
    assert [round(m["natural_frequency_hz"]) for m in modes if claimed(m)] == [29_700]
    assert main_mode(modes)["natural_frequency_hz"] == pytest.approx(29_700)
    alone = modes_of(np.array(pair(18_500, 0.75)), dt, (0.0, 100e3))
    assert main_mode(alone) is None and not alone[0]["resonance"]
