"""The sensitivity of a pulse that drives one direction only (issue 40 items 1 and 5): the
sensitivity this product reports is the mean of both directions (analysis.input_terms), which a
pulse without an opposite lobe does not measure; the asymmetry it cannot fit is carried as a Type
B row of half the stated bound on |ε| (analysis.systematics.one_direction_row).

Found on a world that is not the shipped one: config/sim.toml with the sensor on a separating
mount (`bar_mount = "separating"`: the base flies off, the pulse is compression only) and the
shipped mount's 2 % gain lost in tension. Over 24 shots (plan seed 777) the DC gain read the
compression gain, +1.02 % above the mean of both directions, with a median U of 0.075 %: 0 of 24
intervals held it. With the row (the default bound 3 %), 24 of 24, median U 1.47 %.
"""

from __future__ import annotations

import math

import pytest

from tests.realistic_study import run_shot, world_params

BOUND = 0.03  # AnalysisOptions.asymmetry_bound_rel's default
ROW = "tension/compression asymmetry (one direction driven)"


@pytest.fixture(scope="module")
def shot():
    out = run_shot(world_params("shipped", bar_mount="separating"), 2, 3.0, 1, draws=60, keep_results=True)
    assert out.error is None, out.error
    return out


def test_the_pulse_drives_one_direction_and_epsilon_is_not_fitted(shot) -> None:
    assert shot.truth["asymmetry"] < -0.01  # the shipped mount loses 2 % in tension
    assert shot.value["asymmetry"] is None and "opposite lobe" in shot.not_determined["asymmetry"]


def test_the_dc_gain_interval_holds_the_mean_of_both_directions(shot) -> None:
    lo, hi = shot.interval["sensitivity"]
    truth = shot.truth["sensitivity"]
    assert lo <= truth <= hi, (lo, truth, hi)
    # the value is the compression gain: about |ε|/2 above the mean, which only the row covers
    assert shot.value["sensitivity"] / truth - 1 > 0.3 * abs(shot.truth["asymmetry"])


def test_the_budget_names_the_row_at_half_the_bound(shot) -> None:
    rows = {r["source"]: r for r in shot.results["uncertainty"]["budget"]}
    assert rows[ROW]["kind"] == "Type B"
    assert math.isclose(rows[ROW]["u_rel_by_figure"]["dc_gain"], 0.5 * BOUND / math.sqrt(3), rel_tol=1e-9)
    assert "natural_frequency_hz" not in rows[ROW]["u_rel_by_figure"]  # a gain: the response's shape is not moved


def test_a_pulse_with_both_lobes_has_no_such_row() -> None:
    bonded = run_shot(world_params("shipped"), 2, 3.0, 1, draws=60, keep_results=True)
    assert bonded.error is None, bonded.error
    assert bonded.value["asymmetry"] is not None
    assert ROW not in {r["source"] for r in bonded.results["uncertainty"]["budget"]}
