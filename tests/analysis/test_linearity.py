"""analysis.linearity: a sensitivity against the amplitude (ISO 16063-22).

- the fit against its closed form (points exactly on S₀(1 + c·a));
- statistically: over 2000 synthetic campaigns of six levels with known Gaussian u, the 95 %
  interval of c holds the true c in 95 % of them (a 99 % binomial interval of ±1.3 points);
- on the simulated rig's realistic records (config/sim.toml's effects on), as a campaign's report
  fits it (reports.statistics: each shot's quasi-static gain in the main pulse's direction,
  analysis.static_gain, against the amplitude it is measured at, with the u that differs from shot
  to shot; issue 40 item 5: the peak-ratio S_sh these pulses inflate by ringing the resonance read
  a linear sensor as −1.0 ± 0.75 %, and the model's DC gain read the true −1 % as −0.8 %): a
  sensor with a known non-linearity of −1 % per 100 km/s² (the simulator's Hammerstein input
  a·(1 + c·|a|)) is recovered within the fit's U and told from a linear one, and a linear one gives
  a slope within its U of zero, on shots of two projectiles at four levels;
- the same over independent campaigns (the world's seed changed: other noise, other speeds):
  every one of NON_LINEAR_SEEDS recovers the slope within its U and tells it from zero, and every
  one of LINEAR_SEEDS holds zero. Power: an interval that held the truth in only half the
  campaigns would pass the five non-linear ones with probability 0.5⁵ = 3 %. That test is marked
  `study` (`make studies`, CI after `make test`: 32 shots); `make test` keeps the first two, one
  campaign each.
"""

from __future__ import annotations

import dataclasses
import functools
import os
from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.analysis.linearity import fit_linearity
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.shot_analysis import analyse_raw_shot
from hopkinson.drivers.sim.world import CaptureSettings, simulate_shot
from hopkinson.rig.config import load_sim_config
from tests.rig.conftest import REPO
from tests.shared_results import once_per_run, run_folder

NONLINEARITY = -1.0e-7  # −1 % per 100 km/s²
SHOTS = ((3, 0.6), (2, 1.5), (3, 3.0), (2, 5.0))  # (projectile, bar): about 210 .. 680 km/s² peak, two pulse shapes
NON_LINEAR_SEEDS = (0, 1, 2, 3, 4)  # the world's seed offset of each campaign of a non-linear sensor
LINEAR_SEEDS = (0, 1, 2)


def test_points_on_a_line_give_its_slope_exactly() -> None:
    a = np.array([1e5, 3e5, 5e5, 8e5])
    s0, c = 2.0e-7, -1.0e-7
    fit = fit_linearity(a, s0 * (1 + c * a), np.full(4, 1e-9))
    assert fit.slope_rel_per_m_s2 == pytest.approx(c, rel=1e-9)
    assert fit.reference_sensitivity == pytest.approx(s0, rel=1e-12)
    assert fit.deviation_rel == pytest.approx(c * 7e5, rel=1e-9)
    assert max(abs(r) for r in fit.residuals_rel) < 1e-12
    assert "% per 100 km/s²" in fit.text() and fit.text().startswith("-1 ±")
    with pytest.raises(AnalysisError, match="two or more peak levels"):
        fit_linearity([3e5, 3e5], [1.0, 1.01], [0.01, 0.01])


def test_the_95_percent_interval_of_the_slope_holds_the_truth_95_percent_of_the_time() -> None:
    rng = np.random.default_rng(19)
    a = np.array([1e5, 2e5, 3.5e5, 5e5, 7e5, 9e5])
    s0, c = 1.5, -1.0e-7
    u = 0.004 * s0 * (1 + a / 1e6)  # each point its own u
    campaigns = 2000
    inside = 0
    for _ in range(campaigns):
        s = s0 * (1 + c * a) + rng.standard_normal(a.size) * u
        fit = fit_linearity(a, s, u)
        inside += abs(fit.slope_rel_per_m_s2 - c) <= fit.expanded_slope_rel_per_m_s2
    # 99 % binomial interval of the rate at n = 2000 around 0.95: about ±0.013. The fit only
    # ever widens its u (Birge ratio > 1), so it may sit a little above 0.95.
    assert 0.937 <= inside / campaigns <= 0.975, inside / campaigns


def _campaign(nonlinearity: float, seed: int, tmp_path_factory: pytest.TempPathFactory) -> list[KeyFigures]:
    """The SHOTS through a sensor of `nonlinearity`, in the shipped world with its seed moved by `seed`."""
    return [KeyFigures.from_results(results) for results in campaign_results(nonlinearity, seed, tmp_path_factory)]


def campaign_results(nonlinearity: float, seed: int, tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, ...]:
    """Each of `_campaign`'s shots' results as analyse_raw_shot gives them, computed once per
    test run (tests/lab/test_certificate_linearity.py certifies the same campaign, often on
    another xdist worker: tests/shared_results.py)."""
    return _shared_campaign_results(run_folder(tmp_path_factory), (nonlinearity, seed))


def _shared_campaign_results(folder: Path, key: tuple[float, int]) -> tuple[dict, ...]:
    nonlinearity, seed = key
    return once_per_run(folder, f"linearity-campaign-{nonlinearity:g}-{seed}",
                        functools.partial(_computed_campaign_results, nonlinearity, seed))


def _computed_campaign_results(nonlinearity: float, seed: int) -> tuple[dict, ...]:
    world = load_sim_config(REPO / "config" / "sim.toml").world
    assert world.realism.enabled  # the shipped simulator makes realistic records
    params = dataclasses.replace(world, seed=world.seed + seed, accelerometer=dataclasses.replace(
        world.accelerometer, nonlinearity_per_m_s2=nonlinearity))
    figures = []
    for n, (projectile, pressure) in enumerate(SHOTS, start=1):
        channels, truth = simulate_shot(params, pressure, projectile, CaptureSettings(100e6, 200_000, 20_000),
                                        shot_number=n)
        assert truth["accelerometer"]["nonlinearity_per_m_s2"] == nonlinearity
        result = analyse_raw_shot(channels[1], channels[2], 1e-8, AnalysisOptions(
            amp_gain=truth["amplifier_gain"], sensitivity_v_per_m_s2=truth["sensitivity_v_per_m_s2"],
            max_order=4, draws=60, seed=n), quadrature_v=channels.get(3))
        figures.append(result.to_dict())
    return tuple(figures)


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[float, int], list[KeyFigures]]:
    """Every independent campaign (NON_LINEAR_SEEDS, LINEAR_SEEDS), on the machine's cores."""
    from concurrent.futures import ProcessPoolExecutor

    keys = [(NONLINEARITY, seed) for seed in NON_LINEAR_SEEDS] + [(0.0, seed) for seed in LINEAR_SEEDS]
    folder = run_folder(tmp_path_factory)
    with ProcessPoolExecutor(os.cpu_count() or 1) as pool:
        results = list(pool.map(functools.partial(_shared_campaign_results, folder), keys))
    return {key: [KeyFigures.from_results(r) for r in shots] for key, shots in zip(keys, results, strict=True)}


def _fit(figures: list[KeyFigures]):
    from hopkinson.reports.statistics import campaign_linearity, linearity_points

    points = linearity_points((str(k), kf) for k, kf in enumerate(figures))
    # Every shot that is a result gives its point. A shot is not a result where its DC gain is not
    # determined: through this non-linear sensor, projectile No. 3 at 3 bar (the highest amplitude)
    # leaves a model error of 13× the noise, and on numpy 2.2 / scipy 1.15 its DC gain's interval
    # exceeds half its value (±9 % on newer pairs). The line then goes through the three others.
    assert len(points) == sum(kf.is_result for kf in figures) >= len(figures) - 1, [kf.is_result for kf in figures]
    fit, note = campaign_linearity(points)
    assert fit is not None, note
    return fit


def test_a_known_non_linearity_is_recovered_within_its_uncertainty(tmp_path_factory: pytest.TempPathFactory) -> None:
    fit = _fit(_campaign(NONLINEARITY, 0, tmp_path_factory))
    assert abs(fit.slope_rel_per_m_s2 - NONLINEARITY) <= fit.expanded_slope_rel_per_m_s2, fit.text()
    assert abs(fit.slope_rel_per_m_s2) > fit.expanded_slope_rel_per_m_s2  # told apart from a linear sensor
    # the levels span > 3e5 m/s² (> 2.5e5 with one shot left out, see _fit)
    assert fit.peak_max_m_s2 - fit.peak_min_m_s2 > (3e5 if fit.n == len(SHOTS) else 2.5e5)


def test_a_linear_sensor_has_a_slope_within_its_uncertainty_of_zero(tmp_path_factory: pytest.TempPathFactory) -> None:
    fit = _fit(_campaign(0.0, 0, tmp_path_factory))
    assert abs(fit.slope_rel_per_m_s2) <= fit.expanded_slope_rel_per_m_s2, fit.text()


@pytest.mark.study
def test_every_independent_campaign_finds_the_slope_it_was_given(campaigns) -> None:
    for seed in NON_LINEAR_SEEDS:
        fit = _fit(campaigns[NONLINEARITY, seed])
        assert abs(fit.slope_rel_per_m_s2 - NONLINEARITY) <= fit.expanded_slope_rel_per_m_s2, (seed, fit.text())
        assert abs(fit.slope_rel_per_m_s2) > fit.expanded_slope_rel_per_m_s2, (seed, fit.text())
    for seed in LINEAR_SEEDS:
        fit = _fit(campaigns[0.0, seed])
        assert abs(fit.slope_rel_per_m_s2) <= fit.expanded_slope_rel_per_m_s2, (seed, fit.text())
