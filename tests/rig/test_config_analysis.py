"""The config file's [analysis] / [uncertainty] and a plan's analysis tables are the analysis
options' own declaration (analysis.options), not copies: same defaults, same bounds, and a value
the analysis refuses is refused on load in one line naming the file and the key."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.options import LATER, AnalysisOptions, declared
from hopkinson.rig.config import AnalysisConfig, UncertaintyConfig, load_rig_config
from hopkinson.rig.config_errors import schema
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan import PlanAnalysis

REPO = Path(__file__).resolve().parents[2]
RIG = REPO / "config" / "rig.toml"
RENAMED = {"grating_pitch_rel": "u_grating_pitch_rel", "interferometer_rel": "u_interferometer_rel",
           "amplifier_gain_rel": "u_amp_gain_rel", "digitizer_gain_rel": "u_digitizer_gain_rel",
           "channel_skew_s": "u_channel_skew_s", "amp_gain_2": "amp_gain",
           "sensitivity_2_v_per_m_s2": "sensitivity_v_per_m_s2",
           "transverse_sensitivity_2_rel": "transverse_sensitivity_rel", "asymmetry_bound_2_rel": "asymmetry_bound_rel"}
# keys whose default is "not given": the value comes from elsewhere (the rig's draws; the second
# sensor's stated values: [uncertainty]'s)
UNSET = {PlanAnalysis: {"draws"}, AnalysisConfig: {"transverse_sensitivity_2_rel", "asymmetry_bound_2_rel"}}


@pytest.mark.parametrize("section", [AnalysisConfig, UncertaintyConfig, PlanAnalysis])
def test_every_key_has_the_options_default(section: type) -> None:
    for f in dataclasses.fields(section):
        option = RENAMED.get(f.name, f.name)
        expected = None if f.name in UNSET.get(section, ()) else declared(option)
        assert f.default == expected, (section.__name__, f.name)


@pytest.mark.parametrize(("section", "key", "value"), [
    ("analysis", "dcm_widening", 1.0), ("analysis", "dcm_noise_gain_limit", 0.0), ("analysis", "grating_pitch_m", 0.01),
    ("analysis", "orders", [1, 1]), ("analysis", "amp_gain_2", 0.0), ("uncertainty", "draws", 49),
    ("uncertainty", "amplifier_gain_rel", 0.6), ("uncertainty", "transverse_motion_rel", 1.5),
    ("uncertainty", "asymmetry_bound_rel", -0.01), ("analysis", "transverse_sensitivity_2_rel", 1.5),
    ("analysis", "asymmetry_bound_2_rel", -0.01),
])
def test_what_the_analysis_refuses_the_file_refuses_in_one_line(tmp_path: Path, section: str, key: str,
                                                                value: object) -> None:
    option = RENAMED.get(key, key)
    with pytest.raises(AnalysisError, match=f"analysis option {option}:"):
        AnalysisOptions.from_options(**{option: tuple(value) if isinstance(value, list) else value})
    lines = []
    for line in RIG.read_text().splitlines():  # the key's shipped line goes, the bad value follows the header
        if not line.startswith(f"{key} ="):
            lines.append(line)
        if line.startswith(f"[{section}]"):
            lines.append(f"{key} = {json.dumps(value)}")
    text = "\n".join(lines) + "\n"
    path = tmp_path / "rig.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as caught:
        load_rig_config(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: {section}.{key}: ") and "\n" not in message, message


def test_a_value_the_analysis_takes_loads(tmp_path: Path) -> None:
    """Beyond a copy's old bound: the DCM's noise gain may be unbounded (inf), as for the analysis."""
    text = RIG.read_text().replace("dcm_noise_gain_limit = 4.0", "dcm_noise_gain_limit = inf")
    assert "dcm_noise_gain_limit = inf" in text
    path = tmp_path / "rig.toml"
    path.write_text(text)
    assert load_rig_config(path).analysis.dcm_noise_gain_limit == math.inf


def test_the_schema_bounds_are_the_options_rules() -> None:
    properties = schema(AnalysisConfig)["properties"]
    assert properties["grating_pitch_m"]["maximum"] == 1e-3 and properties["grating_pitch_m"]["exclusiveMinimum"] == 0
    assert "m" in properties["grating_pitch_m"]["description"]  # the unit, from the declaration
    widening = next(a for a in properties["dcm_widening"]["anyOf"] if a.get("type") == "number")
    assert widening["exclusiveMinimum"] == 1


def test_a_shot_file_written_before_reads_back_unchanged() -> None:
    """/analysis/params of a stored shot (a golden written before this type) loads and writes the
    same keys and values; options added since stay out at their defaults."""
    stored = json.loads((REPO / "tests" / "golden" / "outputs" / "sim-shot-3-analysis.json").read_text())["params"]
    options = AnalysisOptions.from_dict(stored)
    assert options.to_dict() == stored
    assert not set(LATER) & set(stored)
    changed = dataclasses.replace(options, significance=0.05, order_draws=20)
    assert AnalysisOptions.from_dict(changed.to_dict()) == changed
    assert changed.to_dict()["significance"] == 0.05
