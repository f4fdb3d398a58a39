"""A conditioner set by hand: plays the amplifier role from the entered values, without I/O."""

from __future__ import annotations

from pathlib import Path

import pytest

from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.manual_conditioner import ManualConditioner
from hopkinson.drivers.roles import AmplifierRole, AmplifierSettings, missing_members
from hopkinson.rig.config import load_rig_config
from hopkinson.rig.instruments import make_instrument

ROOT = Path(__file__).resolve().parents[2]


def test_the_entered_values_are_the_settings_and_nothing_can_be_set() -> None:
    amp = ManualConditioner(gain=31.6, lowpass_hz=30e3, sensitivity_v_per_m_s2=1.2e-5, identity="Kistler 5015A SN 7")
    assert isinstance(amp, AmplifierRole) and missing_members(amp, AmplifierRole) == []
    with amp:
        assert amp.settings() == AmplifierSettings(gain=31.6, excitation_v=0.0, lowpass_hz=30e3, source="entered",
                                                   sensitivity_v_per_m_s2=1.2e-5, identity="Kistler 5015A SN 7")
        amp.configure(gain=31.6, excitation_v=0.0, lowpass_hz=30e3)  # as entered: fine
        with pytest.raises(InstrumentError, match=r"set by hand: .*gain: 31.6 here, 10 there"):
            amp.configure(gain=10.0, excitation_v=0.0, lowpass_hz=30e3)
        assert amp.overloaded() is False and amp.identity() == "Kistler 5015A SN 7"
        amp.auto_zero()
        amp.set_shunt(False)
        with pytest.raises(InstrumentError, match="switch the shunt on at the conditioner"):
            amp.set_shunt(True)
    amp.enter(gain=10.0, lowpass_hz=30e3, identity="Kistler 5015A SN 7")  # the technician changed the gain
    assert amp.settings().gain == 10.0 and amp.settings().sensitivity_v_per_m_s2 is None
    amp.configure(gain=10.0, excitation_v=0.0, lowpass_hz=30e3)
    with pytest.raises(ValueError, match="gain must be > 0"):
        ManualConditioner(gain=0.0)
    with pytest.raises(ValueError, match="lowpass_hz must be a finite number >= 0, got nan"):
        amp.enter(gain=1.0, lowpass_hz=float("nan"))


def test_rig_toml_selects_the_manual_conditioner(tmp_path: Path) -> None:
    text = (ROOT / "config" / "rig.toml").read_text()
    start, end = text.index("[amplifier]"), text.index("[limits]")
    path = tmp_path / "rig.toml"
    path.write_text(text[:start] + '[amplifier]\ndriver = "manual"\ngain = 3.16\nexcitation_v = 0.0\n'
                    'lowpass_hz = 0.0\nsensitivity_v_per_m_s2 = 2.5e-6\nidentity = "PCB 482C"\n\n' + text[end:])
    amp = make_instrument(load_rig_config(path), "amplifier")
    assert isinstance(amp, ManualConditioner)
    assert amp.settings().to_dict() == {"gain": 3.16, "excitation_v": 0.0, "lowpass_hz": 0.0, "source": "entered",
                                        "sensitivity_v_per_m_s2": 2.5e-6, "identity": "PCB 482C"}
