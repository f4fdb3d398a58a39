"""AnalysisParams: one object from plan / CLI to shot file, checked before FIRE."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.params import AnalysisParams


def test_round_trip_through_json_keeps_every_field() -> None:
    params = AnalysisParams(max_order=6, order=4, extra_poles=(0.6 + 0.1j, 0.6 - 0.1j), draws=200, seed=5,
                            u_amp_gain_rel=1e-3, uncertainty=False)
    back = AnalysisParams.from_dict(json.loads(json.dumps(params.to_dict())))
    assert back == params


@pytest.mark.parametrize(
    ("option", "value"),
    [("sample_rate_hz", float("inf")), ("sample_rate_hz", -1.0), ("amp_gain", 0.0), ("max_order", 0),
     ("max_order", 2.5), ("order", 1000), ("draws", 3), ("u_amp_gain_rel", -0.1), ("u_grating_pitch_rel", float("nan")),
     ("grating_pitch_m", 1e300), ("dcm_ratio", -2.0), ("uncertainty", "yes"), ("orders", (1, 1))],
)
def test_check_names_the_option(option: str, value: object) -> None:
    with pytest.raises(AnalysisError, match=f"analysis option {option}"):
        AnalysisParams.from_options(**{option: value})


def test_unknown_options_are_named_unless_reading_results() -> None:
    with pytest.raises(AnalysisError, match="unknown analysis option.*max_ordr"):
        AnalysisParams.from_dict({"max_ordr": 4})
    assert AnalysisParams.from_dict({"max_order": 4, "from_a_newer_version": 1}, ignore_unknown=True).max_order == 4


def test_shot_analysis_re_exports_it() -> None:
    from hopkinson.analysis.shot_analysis import AnalysisParams as Reexported

    assert Reexported is AnalysisParams


def test_importing_it_loads_no_numpy() -> None:
    code = "import sys, hopkinson.analysis.params, hopkinson.analysis.key_figures; print('numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
