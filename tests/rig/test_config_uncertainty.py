"""rig.toml [uncertainty]: the reference chain's relative standard uncertainties, validated on load
and passed to the analysis as AnalysisOptions options."""

from __future__ import annotations

from pathlib import Path

import pytest

from hopkinson.analysis.options import AnalysisOptions
from hopkinson.rig.config import load_rig_config
from hopkinson.rig.errors import ConfigError

RIG = Path(__file__).resolve().parents[2] / "config" / "rig.toml"


def test_shipped_defaults_load_and_become_analysis_options() -> None:
    config = load_rig_config(RIG)
    params = AnalysisOptions.from_options(**config.uncertainty.analysis_options())
    assert params.u_grating_pitch_rel == 1e-4 and params.u_amp_gain_rel == 2e-3 and params.draws == 400


@pytest.mark.parametrize(("line", "bad"), [("grating_pitch_rel = 1e-4", "grating_pitch_rel = -1e-4"),
                                           ("draws = 400", "draws = 5"),
                                           ("channel_skew_s = 1e-9", "channel_skew_s = 1.0")])
def test_a_bad_value_names_the_key(tmp_path: Path, line: str, bad: str) -> None:
    text = RIG.read_text()
    assert line in text
    path = tmp_path / "rig.toml"
    path.write_text(text.replace(line, bad))
    key = bad.split(" =")[0]
    with pytest.raises(ConfigError, match=f"uncertainty.{key}"):
        load_rig_config(path)
