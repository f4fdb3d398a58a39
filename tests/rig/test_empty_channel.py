"""A role mapped to a digitizer channel that carries nothing (issue 44): the rig's interferometer
has one photodetector but rig.toml maps doppler_quadrature to an input with nothing on it. The
shot is recorded, its analysis names the channel and the fix (exit 4, never "the reference's
pulse is lost in its noise"), and `probe`, with that record still in the digitizer, names it too."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from hopkinson.analysis.options import AnalysisOverrides
from hopkinson.rig.cli.main import main
from hopkinson.rig.config import RigConfig
from hopkinson.rig.sequencer import Sequencer
from hopkinson.rig.shot import shot_analyser
from tests.rig.conftest import rig_toml


def quadrature_mapped(config: RigConfig) -> RigConfig:
    """The simulated world has one photodetector (channel 3 holds nothing); map it all the same."""
    d = config.digitizer
    assert "doppler_quadrature" not in d.channels  # --sim would have left it out
    return dataclasses.replace(config, digitizer=dataclasses.replace(
        d, channels={**d.channels, "doppler_quadrature": "CH3"}, ranges_v={**d.ranges_v, "doppler_quadrature": 1.0}))


def test_an_empty_quadrature_channel_is_named_at_analysis_and_at_probe(make_rig, tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    rig = make_rig(adjust=quadrature_mapped)
    rig.sequencer = Sequencer(rig.instruments, rig.config, rig.bus, analyse=shot_analyser(rig.config))
    outcome = rig.run(pressure_bar=2.0, analysis=AnalysisOverrides(uncertainty=False, max_order=6))
    assert outcome.final_state == "DONE" and outcome.exit_code == 4 and outcome.shot_path is not None
    assert "the doppler_quadrature channel carries no beat" in outcome.analysis_error
    assert "unmap the quadrature channel (digitizer.channels.doppler_quadrature" in outcome.analysis_error
    assert "lost in its noise" not in outcome.analysis_error
    rig.assert_safe()
    assert rig.session.rig.digitizer.state == "TRIGGERED"  # the record is still in the digitizer

    toml = rig_toml(rig.session, tmp_path / "rig.toml")  # config/rig-sim.toml maps doppler_quadrature = "CH3"
    rig.instruments.close()
    assert main(["probe", "--config", str(toml), "--json"]) == 1
    steps = {s["step"]: s for s in json.loads(capsys.readouterr().out)["instruments"]["digitizer"]["steps"]}
    empty = steps["doppler_quadrature (CH3) carries its signal"]
    assert empty["ok"] is False and empty["error"].startswith("the doppler_quadrature channel carries no beat")
    assert empty["fix"].startswith("unmap the quadrature channel: remove digitizer.channels.doppler_quadrature")
    assert steps["response (CH2) carries its signal"]["ok"] is True
