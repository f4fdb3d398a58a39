"""The identification's trail is told by its stages, and no result is written after it is built:
a sensor of known f_n (27 kHz), ζ and gain behind a half-sine with white noise (as
test_identify_stages), so the trail's figures are checked against the simulation's truth."""

from __future__ import annotations

import dataclasses
import re

import pytest

from hopkinson.analysis.identify import identify
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.shot_analysis import with_uncertainty
from hopkinson.analysis.trail import HEADING, Stage, Step, Stretch, Trail, motion_lines
from tests.analysis.test_identify_stages import F_N_HZ, ZETA, record


@pytest.fixture(scope="module")
def ident():
    return identify(record(seed=6), sample_rate_hz=None)


def test_the_trail_names_the_known_mode_and_each_stages_decision(ident):
    trail = ident.trail
    assert trail.text().splitlines()[0] == HEADING
    assert all(line.startswith("  ") for line in trail.text().splitlines()[1:])
    prepare = trail.of(Stage.PREPARE)
    assert prepare[0].startswith("noise (RMS, channel units): reference ")
    assert any(line.startswith("band: ") for line in prepare)
    assert trail.of(Stage.SEARCH_ORDERS)[0].startswith("V by order: 1: ")
    assert trail.of(Stage.SETTLE)[0].startswith(f"order {ident.order} (order_test): the smallest order")
    assert ident.order == 2  # the simulated sensor's order
    assert trail.of(Stage.WEIGH_MODEL_ERROR)[0].startswith("model error: none beyond the noise")
    claimed = [line for line in trail.of(Stage.CLAIM) if line.endswith("claimed (inside the band)")]
    assert len(claimed) == 1
    found = re.match(r"pole pair at ([0-9.]+) kHz, ζ ([0-9.]+)", claimed[0])
    assert found and float(found.group(1)) * 1e3 == pytest.approx(F_N_HZ, rel=0.01)
    assert float(found.group(2)) == pytest.approx(ZETA, rel=0.1)
    # the noise line's figures are the report's (one account of the noise stage)
    noise = ident.to_dict()["noise"]
    assert f"reference {noise['reference_rms']:.4g} ({noise['reference_source']})" in prepare[0]


def test_a_trail_is_its_steps_in_order():
    trail = Trail((Step(Stage.PREPARE, "a"), Step(Stage.CLAIM, "b"), Step(Stage.PREPARE, "c")))
    assert trail.of(Stage.PREPARE) == ["a", "c"] and trail.of(Stage.SETTLE) == []
    assert trail.text() == f"{HEADING}\n  a\n  b\n  c"


def test_motion_measured_as_noise_all_the_same_says_so():
    line, = motion_lines([Stretch(1e-3, 2e-3, None, "")], kept=True)
    assert line == ("motion: 1–2 ms too short to judge by coherence: measured as noise all the same, there being "
                    "no lead-in at rest")


def test_the_identification_is_frozen_and_the_uncertainty_gives_a_new_one(ident):
    with pytest.raises(dataclasses.FrozenInstanceError):
        ident.order_evidence = None  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        ident.settlement.sweep.why = "changed"  # type: ignore[misc]
    before = ident.to_dict()
    fitted = with_uncertainty(ident, AnalysisOptions(draws=40, seed=1))
    assert ident.to_dict() == before  # the identification at hand (a session cache's) is left as it was
    assert ident.order_evidence.stability is None
    stability = fitted.identification.order_evidence.stability
    assert stability.draws == fitted.uncertainty["order"]["draws"] > 0
    assert stability.fraction_by_order == fitted.uncertainty["order"]["fraction_by_order"]
    assert fitted.identification.trail is ident.trail
