"""The model-structure row's rule (analysis.systematics.band_tests_shape, variant_bounds): the
structure variants enter by their evidence only where the supported band reaches past the
resonance to where the chosen model's response has fallen to a third of its DC gain; elsewhere
the rectangle of the largest shift. Checked against closed forms of a second-order sensor."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.systematics import (
    SHAPE_FALL,
    _largest_shift,
    akaike_weight,
    band_tests_shape,
    evidence_scale,
)

FN = 30e3
ZETA = 0.05
DT = 1e-7  # 10 MS/s: the discrete image's own bend, (πf/fs)², is 4e-4 at 2 f_n, far inside the margins


def sensor(gain: float = 1.0) -> DiscreteModel:
    """A second-order sensor (f_n, ζ), its poles at exp(sT), its numerator flat, DC gain `gain`."""
    s = -ZETA * 2 * math.pi * FN + 1j * 2 * math.pi * FN * math.sqrt(1 - ZETA**2)
    z = np.exp(s * DT)
    a = np.real(np.poly([z, np.conj(z)]))
    return DiscreteModel(DT, a, np.array([gain * np.sum(a)]))


def ident(top_hz: float, fn_hz: float | None = FN) -> SimpleNamespace:
    main = None if fn_hz is None else SimpleNamespace(natural_frequency_hz=fn_hz)
    return SimpleNamespace(main_mode=main, supported_band_hz=(100.0, top_hz))


def third_ratio() -> float:
    """r where 1/√((1 − r²)² + (2ζr)²) = 1/3, i.e. (r²)² − 2(1 − 2ζ²)r² − 8 = 0:
    r² = 1 − 2ζ² + √((1 − 2ζ²)² + 8)."""
    b = 1 - 2 * ZETA**2
    return math.sqrt(b + math.sqrt(b * b + 8.0))


def test_the_share_is_a_third_an_octave_above_a_single_mode() -> None:
    assert SHAPE_FALL == pytest.approx(1 / 3)
    assert third_ratio() == pytest.approx(2.0, abs=0.005)  # ζ = 0.05: 1.9987


@pytest.mark.parametrize("gain", [1.0, -2.5])  # the DC gain's sign and size do not matter
def test_the_band_tests_the_shape_only_past_where_the_response_fell_to_a_third(gain: float) -> None:
    r = third_ratio()
    model = sensor(gain)
    assert not band_tests_shape(ident(0.98 * r * FN), model)
    assert band_tests_shape(ident(1.02 * r * FN), model)
    # a band that ends below the resonance, or at 1.5 f_n (past the peak, where the response is
    # back under its DC level but not yet down to a third), does not
    assert not band_tests_shape(ident(0.8 * FN), model)
    assert not band_tests_shape(ident(1.5 * FN), model)
    assert band_tests_shape(ident(5.0 * FN), model)
    # no resonance claimed: never
    assert not band_tests_shape(ident(5.0 * FN, fn_hz=None), model)


def test_each_structure_variants_shift_is_weighed_by_its_own_evidence() -> None:
    """_largest_shift with one factor per variant: the largest of the weighed shifts, signed; with
    none, the largest whole shift (the rectangle) as before."""
    nominal = {"dc_gain": 1.0, "fbsd_5_hz": 6000.0}
    variants = [{"dc_gain": 1.002, "fbsd_5_hz": 6030.0}, {"dc_gain": 0.999, "fbsd_5_hz": 5990.0}]
    assert _largest_shift(nominal, variants) == pytest.approx({"dc_gain": 0.002, "fbsd_5_hz": 30.0})
    # the first variant rejected by the record (w = 1e-4), the second favoured (whole)
    w = [1e-4, 0.9]
    scales = [evidence_scale(x) for x in w]
    assert scales[1] == 1.0 and scales[0] == pytest.approx(math.sqrt(3e-4))
    shifts = _largest_shift(nominal, variants, scales)
    assert shifts["dc_gain"] == pytest.approx(-0.001)
    assert shifts["fbsd_5_hz"] == pytest.approx(-10.0)
    # both rejected: each at √(3w) of its own shift, the larger kept
    shifts = _largest_shift(nominal, variants, [math.sqrt(3e-4), math.sqrt(3e-2)])
    assert shifts["fbsd_5_hz"] == pytest.approx(-10.0 * math.sqrt(3e-2))
    # a figure the nominal lacks, or a non-finite one, is no shift
    assert _largest_shift({"dc_gain": 1.0}, [{"dc_gain": math.nan, "x": 2.0}], [1.0]) == {}


def test_a_structure_with_fewer_parameters_is_weighed_by_the_same_akaike_weight() -> None:
    """The other structure at the chosen order has fewer parameters (its zeros fixed): Δk < 0
    counts for it; 21.6 worse for 2 fewer, no over-dispersion: w = 1/(1 + e^19.6)."""
    chosen = SimpleNamespace(cost=100.0, parameters=18)
    other = SimpleNamespace(cost=121.6, parameters=16)
    assert akaike_weight(other, chosen, 1000.0) == pytest.approx(1 / (1 + math.exp(19.6)), rel=1e-12)


def test_an_all_pole_choice_keeps_the_rectangle_whatever_the_band() -> None:
    """evidence_judges_structure: evidence only where the band tests the shape and the chosen
    model's zeros are free; the all-pole structure's numerator (1 + z⁻¹)²/4 is a bound. Its bias
    against a continuous second-order sensor, in closed form: |H(f)|/|H(0)| of the bilinear
    numerator is cos²(πf·T), a droop of (πfT)² at order 2, the same at any band's width."""
    from hopkinson.analysis.systematics import evidence_judges_structure

    free = SimpleNamespace(numerator=None)
    all_pole = SimpleNamespace(numerator=np.array([1.0, 2.0, 1.0]) / 4.0)
    assert evidence_judges_structure(free, True)
    assert not evidence_judges_structure(free, False)
    assert not evidence_judges_structure(all_pole, True)
    assert not evidence_judges_structure(all_pole, False)
    # the droop the likelihood would have to see: at 6.5 kHz and 1 MS/s, 4.2e-4 of the gain
    f, t = 6.5e3, 1e-6
    w = 2 * math.pi * f * t
    droop = 1 - abs((1 + np.exp(-1j * w)) ** 2 / 4)
    assert droop == pytest.approx(math.sin(math.pi * f * t) ** 2, rel=1e-9)
    assert droop == pytest.approx((math.pi * f * t) ** 2, rel=1e-3)
