"""AnalysisOptions: one object from plan / CLI to shot file, checked before FIRE."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.options import AnalysisOptions


def test_round_trip_through_json_keeps_every_field() -> None:
    params = AnalysisOptions(max_order=6, order=4, extra_poles=(0.6 + 0.1j, 0.6 - 0.1j), draws=200, seed=5,
                            u_amp_gain_rel=1e-3, uncertainty=False)
    back = AnalysisOptions.from_dict(json.loads(json.dumps(params.to_dict())))
    assert back == params


@pytest.mark.parametrize(
    ("option", "value"),
    [("sample_rate_hz", float("inf")), ("sample_rate_hz", -1.0), ("amp_gain", 0.0), ("max_order", 0),
     ("max_order", 2.5), ("order", 1000), ("draws", 3), ("u_amp_gain_rel", -0.1), ("u_grating_pitch_rel", float("nan")),
     ("grating_pitch_m", 1e300), ("dcm_ratio", -2.0), ("uncertainty", "yes"), ("orders", (1, 1))],
)
def test_check_names_the_option(option: str, value: object) -> None:
    with pytest.raises(AnalysisError, match=f"analysis option {option}"):
        AnalysisOptions.from_options(**{option: value})


def test_unknown_options_are_named_unless_reading_results() -> None:
    with pytest.raises(AnalysisError, match="unknown analysis option.*max_ordr"):
        AnalysisOptions.from_dict({"max_ordr": 4})
    assert AnalysisOptions.from_dict({"max_order": 4, "from_a_newer_version": 1}, ignore_unknown=True).max_order == 4


def test_shot_analysis_re_exports_it() -> None:
    from hopkinson.analysis.shot_analysis import AnalysisOptions as Reexported

    assert Reexported is AnalysisOptions


def test_importing_it_loads_no_numpy() -> None:
    code = "import sys, hopkinson.analysis.options, hopkinson.analysis.key_figures; print('numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# Each DCM option at and around the edges of what the design accepts (the design itself is the
# truth: a shot whose options pass check() must never be refused by the DCM after FIRE). What
# only the shot's model can tell (more extra poles than cancelled poles, a band limit above a
# slower record's Nyquist, a design so slow — r or ζ_e ~1e-6 — that its noise gain cannot be
# evaluated) is outside check()'s reach.
_NAN, _INF = float("nan"), float("inf")
DCM_CASES = (
    [("dcm_damping", v) for v in (-0.1, 0.0, 1e-3, 0.5, 1.0, 1.0 + 1e-9, 2.0, 10.0, _NAN, _INF)]
    + [("dcm_ratio", v) for v in (None, -1.0, 0.0, 0.5, 10.0, 1e5, _NAN, _INF)]
    + [("dcm_widening", v) for v in (0.5, 1.0, 1.0 + 1e-9, 3.0, 5e3, _NAN, _INF)]
    + [("dcm_noise_gain_limit", v) for v in (-1.0, 0.0, 1e-3, 4.0, 1e9, _NAN, _INF)]
    + [("dcm_band_limit_hz", v) for v in (None, -1.0, 0.0, 40e3, 499_999.0, 500_000.0, 2e6, _NAN, _INF)]
    + [("extra_poles", v) for v in ((), (0.5,), (0.5 + 0.1j, 0.5 - 0.1j), (0.5 + 0.1j,), (1.0,), (-1.5,),
                                    (complex(_NAN, 0.0),))]
)


def _design_refuses(option: str, value: object) -> bool:
    """Whether the DCM design (AnalysisOptions without a rate, design_compensation on a 27 kHz sensor's shot at
    1 MS/s with room for two extra poles) refuses the option."""
    import numpy as np

    from hopkinson.analysis.dcm_design import ShotSupport, design_compensation
    from hopkinson.analysis.model import DiscreteModel

    dt = 1e-6
    poles = []
    for f_n, zeta in ((27_000.0, 0.05), (60_000.0, 0.3)):
        s = 2 * np.pi * f_n * (-zeta + 1j * np.sqrt(1 - zeta**2))
        poles += [np.exp(s * dt), np.exp(np.conj(s) * dt)]
    a = np.real(np.poly(poles))
    model = DiscreteModel(dt, a, np.array([np.sum(a)]))
    try:  # the design alone: no analysis rate given, the model's bounds the band limit
        options = AnalysisOptions(sample_rate_hz=None, **{option: value})
        design_compensation(ShotSupport(model, None, supported_band_hz=(0.0, 60_000.0)), options)
    except AnalysisError:
        return True
    return False


@pytest.mark.parametrize(("option", "value"), DCM_CASES)
def test_check_refuses_exactly_what_the_dcm_design_refuses(option: str, value: object) -> None:
    try:
        AnalysisOptions.from_options(**{option: value}) if value is not None else AnalysisOptions(**{option: value})
        refused = False
    except AnalysisError as exc:
        refused = True
        assert f"analysis option {option}:" in str(exc)
    assert refused == _design_refuses(option, value), (option, value)


def test_the_dcm_defaults_have_one_definition() -> None:
    from hopkinson.analysis import dcm_design
    from hopkinson.analysis import options as declared

    assert not hasattr(dcm_design, "DEFAULT_WIDENING") and not hasattr(dcm_design, "DEFAULT_DAMPING")
    assert not hasattr(dcm_design, "DcmOptions")  # the design takes the one options type
    defaults = AnalysisOptions()
    assert (defaults.dcm_widening, defaults.dcm_damping, defaults.dcm_noise_gain_limit) == (
        declared.DEFAULT_DCM_WIDENING, declared.DEFAULT_DCM_DAMPING, declared.DEFAULT_DCM_NOISE_GAIN_LIMIT)
