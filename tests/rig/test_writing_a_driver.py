"""docs/writing-a-driver.md, run: the example driver (docs/examples/lab_charge_amp.py) named in a
rig.toml by module and class, loaded and checked against its role, driven over a simulated
serial line; the page's own snippets are the ones executed."""

from __future__ import annotations

import re
import textwrap
from collections.abc import Iterator
from importlib import metadata
from pathlib import Path

import pytest

from hopkinson.drivers.roles import AmplifierRole, AmplifierSettings
from hopkinson.drivers.sim.serial_line import PtyLine, byte_time_s
from hopkinson.rig.config import load_rig_config
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.instruments import make_instrument

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "writing-a-driver.md"


def blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


@pytest.fixture
def examples(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The docs' example folder on the import path, as a lab's folder on PYTHONPATH would be."""
    monkeypatch.syspath_prepend(str(ROOT / "docs" / "examples"))
    yield


@pytest.fixture
def device(examples: None) -> Iterator[PtyLine]:
    from lab_charge_amp import FakeChargeAmp

    with PtyLine(byte_time_s(9600)) as line, FakeChargeAmp(line.device_fd):
        yield line


def rig_toml(tmp_path: Path, amplifier_section: str) -> Path:
    """config/rig.toml with its [amplifier] section replaced."""
    text = (ROOT / "config" / "rig.toml").read_text()
    start, end = text.index("[amplifier]"), text.index("[limits]")
    path = tmp_path / "rig.toml"
    path.write_text(text[:start] + amplifier_section + "\n" + text[end:])
    return path


def test_the_pages_rig_toml_loads_the_class_and_drives_the_instrument(tmp_path: Path, device: PtyLine) -> None:
    snippet = blocks("toml")[0]
    assert 'driver = "lab_charge_amp:ChargeAmplifier"' in snippet
    config = load_rig_config(rig_toml(tmp_path, snippet.replace("/dev/ttyUSB3", device.port)))
    amp = make_instrument(config, "amplifier")
    assert type(amp).__name__ == "ChargeAmplifier" and isinstance(amp, AmplifierRole)
    records = []
    amp.trace = records.append
    with amp:
        a = config.amplifier
        amp.configure(gain=a.gain, excitation_v=a.excitation_v, lowpass_hz=a.lowpass_hz)
        assert amp.settings() == AmplifierSettings(gain=100.0, excitation_v=0.0, lowpass_hz=30000.0)
        assert amp.identity() == "ACME,CA-2,SN42,1.3" and amp.overloaded() is False
        amp.auto_zero()
        amp.set_shunt(False)
    assert ("->", "GAIN 100") in [(r.direction, r.text) for r in records]
    assert ("<-", "OK") in [(r.direction, r.text) for r in records]


def test_the_pages_try_it_snippet_runs(examples: None) -> None:
    (snippet,) = [b for b in blocks("python") if "PtyLine" in b]
    exec(compile(textwrap.dedent(snippet), str(DOC), "exec"), {})  # noqa: S102 - the page's own code


def test_a_class_that_misses_a_method_is_named_at_load(tmp_path: Path, examples: None,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    import lab_charge_amp

    monkeypatch.delattr(lab_charge_amp.ChargeAmplifier, "overloaded")  # a driver written without it
    path = rig_toml(tmp_path, '[amplifier]\ndriver = "lab_charge_amp:ChargeAmplifier"\n'
                              '[amplifier.options]\nport = "/dev/null"\n')
    with pytest.raises(ConfigError, match=r"amplifier.driver: driver 'lab_charge_amp:ChargeAmplifier' cannot be "
                                          r"the amplifier: it has no overloaded \(see docs/writing-a-driver.md\)"):
        load_rig_config(path)


def test_an_option_the_class_does_not_take_is_named(tmp_path: Path, examples: None) -> None:
    path = rig_toml(tmp_path, '[amplifier]\ndriver = "lab_charge_amp:ChargeAmplifier"\n'
                              '[amplifier.options]\nport = "/dev/null"\nspeed = 9600\n')
    config = load_rig_config(path)
    with pytest.raises(ConfigError, match=r"amplifier.options: lab_charge_amp:ChargeAmplifier does not accept "
                                          r"them: .*unexpected keyword argument 'speed'"):
        make_instrument(config, "amplifier")


def test_an_entry_point_names_the_class(tmp_path: Path, device: PtyLine, monkeypatch: pytest.MonkeyPatch) -> None:
    point = metadata.EntryPoint(name="acme-ca2", value="lab_charge_amp:ChargeAmplifier", group="hopkinson.drivers")
    real = metadata.entry_points

    def entry_points(**selection: str) -> metadata.EntryPoints:
        if selection.get("group") == "hopkinson.drivers":
            return metadata.EntryPoints([point] if selection.get("name", "acme-ca2") == "acme-ca2" else [])
        return real(**selection)

    monkeypatch.setattr(metadata, "entry_points", entry_points)
    path = rig_toml(tmp_path, f'[amplifier]\ndriver = "acme-ca2"\ngain = 10.0\nexcitation_v = 0.0\n'
                              f'[amplifier.options]\nport = "{device.port}"\n')
    with make_instrument(load_rig_config(path), "amplifier") as amp:
        assert amp.identity() == "ACME,CA-2,SN42,1.3"
    with pytest.raises(ConfigError, match="no driver 'acme-ca3'.*installed: acme-ca2"):
        load_rig_config(rig_toml(tmp_path, '[amplifier]\ndriver = "acme-ca3"\n'))
