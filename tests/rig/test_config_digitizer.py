"""[digitizer] of rig.toml: dialect, VISA set-up, channels by role and ranges, checked at load
with one line naming the file and the key; the settings it asks for, in the dialect's names."""

from __future__ import annotations

from pathlib import Path

import pytest

from hopkinson.drivers.digitizer import Digitizer
from hopkinson.drivers.digitizer_settings import DigitizerSettings
from hopkinson.rig.config import load_rig_config
from hopkinson.rig.errors import ConfigError

HEAD = ('[valve_controller]\nhost = "10.0.0.5"\n[amplifier]\nport = "/dev/ttyS0"\n'
        '[limits]\nmax_pressure_bar = 8.0\nmin_pressure_bar = 0.2\npressure_tolerance_bar = 0.05\n'
        'fixture_vacuum_max_mbar = 100.0\nvent_done_bar = 0.05\n')


def load(tmp_path: Path, digitizer: str) -> object:
    path = tmp_path / "rig.toml"
    path.write_text(HEAD + '[digitizer]\nresource = "TCPIP0::10.0.0.6::5025::SOCKET"\n' + digitizer)
    return load_rig_config(path).digitizer


def test_a_keysight_rig_by_role(tmp_path: Path) -> None:
    d = load(tmp_path, 'dialect = "keysight"\nvisa_library = "/opt/keysight/iolibs/libvisa.so"\n'
                       'read_termination = "\\r\\n"\nsample_format = "uint8"\ntrigger_source = "response"\n'
                       'pre_trigger_fraction = 0.25\nrecord_length = 40000\n'
                       '[digitizer.channels]\ndoppler = "CHANnel1"\ndoppler_quadrature = "chan3"\nresponse = "4"\n'
                       '[digitizer.ranges_v]\ndoppler = 0.5\ndoppler_quadrature = 0.5\nresponse = 8.0\n')
    assert d.channels == {"doppler": "CHAN1", "doppler_quadrature": "CHAN3", "response": "CHAN4"}
    assert d.settings() == DigitizerSettings(
        sample_rate_hz=100e6, record_length=40_000, pre_trigger_samples=10_000,
        ranges_v={"CHAN1": 0.5, "CHAN3": 0.5, "CHAN4": 8.0}, trigger_source="CHAN4", trigger_level_v=0.2,
        trigger_slope="POS")
    dig = Digitizer(**d.driver_options())
    assert dig.dialect.name == "keysight" and dig.channels == d.channels
    assert dig._link.library == "/opt/keysight/iolibs/libvisa.so" and dig._link.read_termination == "\r\n"
    assert dig.dialect.transfer.sample_format == "uint8"


def test_the_older_range_keys_still_name_channels_1_and_2(tmp_path: Path) -> None:
    d = load(tmp_path, "ch1_range_v = 2.0\nch2_range_v = 5.0\n")
    assert d.settings().ranges_v == {"CH1": 2.0, "CH2": 5.0}


@pytest.mark.parametrize(("text", "words"), [
    ('dialect = "agilent"', "digitizer: dialect: unknown dialect 'agilent'"),
    ('dialect = "mylab.nothere:Scope"', "digitizer: dialect: dialect 'mylab.nothere:Scope': cannot import"),
    ('dialect = "lecroy"\nsample_format = "float32"', "sample_format: must be one of int8, int16 for the lecroy"),
    ('sample_format = "int12"', "digitizer.sample_format: must be one of"),
    ('byte_order = "middle"', "digitizer.byte_order: must be one of little, big"),
    ('write_termination = ""', "write_termination: must be one or two ASCII characters"),
    ('max_reply_bytes = 10', "digitizer.max_reply_bytes: must be at least 64"),
    ('trigger_source = "CH7"', "trigger_source: 'CH7' is not a trigger source of a generic digitizer"),
    ('dialect = "lecroy"\n[digitizer.channels]\ndoppler = "C1"\nresponse = "CH9"',
     "channels.response: 'CH9' is not a channel of a lecroy digitizer (channels: C1, C2, C3, C4)"),
    ('[digitizer.channels]\ndoppler = "CH1"\nresponse = "CH2"\nvelocity = "CH3"', "channels.velocity: not a role"),
    ('[digitizer.channels]\ndoppler = "CH1"', "channels.response: missing key"),
    ('[digitizer.channels]\ndoppler = "CH1"\nresponse = "ch1"', "channels: two roles on one channel"),
    ('[digitizer.channels]\ndoppler = "CH1"\nresponse = "CH3"', "ranges_v.response: missing key (the range of CH3)"),
    ('[digitizer.ranges_v]\nresponse_2 = 1.0', "ranges_v.response_2: no such role in [digitizer.channels]"),
    ('[digitizer.ranges_v]\nresponse = 0.0', "digitizer: ranges_v.response: must be above 0 and at most 100 V"),
    ('[digitizer.ranges_v]\nresponse = "ten"', "digitizer: ranges_v.response: must be above 0 and at most 100 V"),
    ('[digitizer.options]\nport = 1', "digitizer: options: only for a lab's own driver"),
])
def test_bad_digitizer_keys_are_one_line_naming_the_key(tmp_path: Path, text: str, words: str) -> None:
    with pytest.raises(ConfigError) as info:
        load(tmp_path, text + "\n")
    message = str(info.value)
    assert words in message and str(tmp_path / "rig.toml") in message and "\n" not in message
