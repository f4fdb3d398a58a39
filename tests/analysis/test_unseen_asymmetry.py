"""The Type B row of an asymmetry the record does not show beyond chance (analysis.systematics):
its bound is the figures' change at max(2u, |ε̂|), scaled from the refit's ε̂ (the change is
linear in ε). Closed-form checks of the scale; the old rule failed the first two."""

import pytest

from hopkinson.analysis.systematics import unseen_asymmetry_scale


@pytest.mark.parametrize(("epsilon", "u", "bound"), [
    (0.05e-3, 1e-3, 2e-3),   # |ε̂| < 0.1 u: the old rule kept ε̂ itself, a bound of 0.05 u
    (-3.0e-3, 1e-3, 3e-3),   # 2u < |ε̂| < 3.29 u: the old rule bounded at 2u, below the estimate
    (1.0e-3, 1e-3, 2e-3),
    (-0.4e-3, 1e-3, 2e-3),
])
def test_unseen_asymmetry_is_bounded_at_twice_its_u_or_its_estimate(epsilon: float, u: float, bound: float) -> None:
    assert abs(epsilon) * unseen_asymmetry_scale(epsilon, u) == pytest.approx(bound, rel=1e-12)


def test_a_vanishing_estimate_is_scaled_at_most_200_times() -> None:
    assert unseen_asymmetry_scale(1e-9, 1e-3) == pytest.approx(200.0)
    assert unseen_asymmetry_scale(0.0, 1e-3) == pytest.approx(200.0)
