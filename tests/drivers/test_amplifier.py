"""The bridge amplifier: framing bytes, a scripted peer on a pty, and the simulated amplifier."""

from __future__ import annotations

import contextlib
import os
import select
import threading
import tty
from collections.abc import Callable, Iterator
from functools import reduce

import pytest
import serial

from hopkinson.drivers.amplifier import (
    BridgeAmplifier,
    FramingError,
    checksum,
    frame,
    parse_line,
)
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.sim.simulated_rig import SimulatedRig


def xor_hex(text: str) -> str:
    """Independent checksum: XOR of the payload's bytes, two upper-case hex digits."""
    return format(reduce(lambda acc, b: acc ^ b, text.encode("ascii"), 0), "02X")


# -- framing, byte for byte -------------------------------------------------------------------
def test_checksum_is_the_xor_of_the_payload_bytes() -> None:
    assert checksum("GAIN 20") == xor_hex("GAIN 20") == "23"
    assert checksum("") == "00"
    assert checksum(b"A") == "41"
    assert checksum("AB") == "03"  # 0x41 ^ 0x42


def test_frame_is_payload_star_checksum_newline() -> None:
    assert frame("GAIN 20") == b"GAIN 20*23\n"
    assert frame("*IDN?") == f"*IDN?*{xor_hex('*IDN?')}\n".encode()
    with pytest.raises(ValueError):
        frame("two\nlines")


def test_parse_line_accepts_good_lines() -> None:
    assert parse_line(b"GAIN OK*25\n") == "GAIN OK"
    assert parse_line(b"GAIN OK*25\r\n") == "GAIN OK"
    assert parse_line(b"gain ok*" + xor_hex("gain ok").lower().encode() + b"\n") == "gain ok"
    idn = "*IDN Hopkinson-Sim,SIMAMP-1,SIM0002,1.0"  # a '*' inside the payload: the last one counts
    assert parse_line(f"{idn}*{xor_hex(idn)}\n".encode()) == idn
    assert parse_line(b"GAIN?\n", require_checksum=False) == "GAIN?"


@pytest.mark.parametrize(
    ("line", "problem"),
    [
        (b"GAIN OK*26\n", "checksum mismatch: line says 26, payload gives 25"),
        (b"GAIJ OK*25\n", "checksum mismatch"),
        (b"GAIN OK\n", "no \\*XX checksum"),
        (b"GAIN OK*2\n", "no \\*XX checksum"),
        (b"GAIN OK*ZZ\n", "no \\*XX checksum"),
        (b"GAIN OK*25", "not terminated"),
        (b"GAIN \xff*25\n", "non-ASCII"),
    ],
)
def test_parse_line_rejects_bad_lines(line: bytes, problem: str) -> None:
    with pytest.raises(FramingError, match=problem):
        parse_line(line)


# -- the driver against a scripted peer on a pty ------------------------------------------------
class ScriptedPeer:
    """The far end of a pty: records every line the driver sends and answers with `reply(line)`."""

    def __init__(self, reply: Callable[[bytes], bytes | None]) -> None:
        self.reply = reply
        self.received: list[bytes] = []
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scripted-amp", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        buffer = b""
        while not self._stop.is_set():
            if not select.select([self.master], [], [], 0.02)[0]:
                continue
            try:
                buffer += os.read(self.master, 1024)
            except OSError:
                continue
            while b"\n" in buffer:
                line, buffer = buffer.split(b"\n", 1)
                self.received.append(line + b"\n")
                out = self.reply(line + b"\n")
                if out:
                    os.write(self.master, out)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


@pytest.fixture
def peer_factory() -> Iterator[Callable[[Callable[[bytes], bytes | None]], ScriptedPeer]]:
    peers: list[ScriptedPeer] = []

    def make(reply: Callable[[bytes], bytes | None]) -> ScriptedPeer:
        peers.append(ScriptedPeer(reply))
        return peers[-1]

    yield make
    for p in peers:
        p.close()


def test_driver_sends_framed_commands_and_parses_the_reply(peer_factory) -> None:
    peer = peer_factory(lambda line: b"GAIN 20*" + xor_hex("GAIN 20").encode() + b"\n")
    with BridgeAmplifier(peer.port, timeout_s=1.0) as amp:
        assert amp.gain() == 20.0
    assert peer.received == [b"GAIN?*" + xor_hex("GAIN?").encode() + b"\n"]


def test_wrong_checksum_is_retried_then_reported_with_the_reply(peer_factory) -> None:
    peer = peer_factory(lambda line: b"GAIN 20*00\n")
    with BridgeAmplifier(peer.port, timeout_s=1.0, retries=2, name="amp (scripted)") as amp:
        with pytest.raises(InstrumentError) as caught:
            amp.gain()
    assert not isinstance(caught.value, InstrumentTimeout)
    assert caught.value.instrument == "amp (scripted)"
    assert caught.value.command == "GAIN?"
    assert "checksum mismatch" in caught.value.problem
    assert "GAIN 20*00" in caught.value.reply
    assert len(peer.received) == 3  # first try + 2 retries


def test_one_noisy_reply_is_recovered_by_the_retry(peer_factory) -> None:
    answers = iter([b"GAIN 2O*23\n", b"GAIN 50*" + xor_hex("GAIN 50").encode() + b"\n"])
    peer = peer_factory(lambda line: next(answers))
    with BridgeAmplifier(peer.port, timeout_s=1.0, retries=1) as amp:
        assert amp.gain() == 50.0
    assert len(peer.received) == 2


def test_a_reply_to_another_command_is_not_taken(peer_factory) -> None:
    peer = peer_factory(lambda line: frame("EXC 5.000"))
    with BridgeAmplifier(peer.port, timeout_s=1.0, retries=0) as amp:
        with pytest.raises(InstrumentError, match="reply is not for 'GAIN'"):
            amp.gain()
    assert len(peer.received) == 1


def test_silence_is_a_timeout(peer_factory) -> None:
    peer = peer_factory(lambda line: None)
    with BridgeAmplifier(peer.port, timeout_s=0.2, retries=0) as amp:
        with pytest.raises(InstrumentTimeout, match=r"'OVL\?': no complete reply within 0.2 s"):
            amp.overloaded()
    assert peer.received == [frame("OVL?")]


def test_an_err_reply_is_a_refusal_without_retry(peer_factory) -> None:
    peer = peer_factory(lambda line: frame("GAIN ERR RANGE"))
    with BridgeAmplifier(peer.port, timeout_s=1.0, retries=3) as amp:
        with pytest.raises(InstrumentError, match="amplifier refused: RANGE"):
            amp.query("GAIN 3")
    assert peer.received == [frame("GAIN 3")]


def test_unknown_port_is_a_connection_error() -> None:
    with pytest.raises(InstrumentConnectionError, match=r"bridge amplifier /nonexistent/tty: 'open'"):
        BridgeAmplifier("/nonexistent/tty").connect()


# -- every operation against the simulated amplifier ----------------------------------------------
def amplifier(rig: SimulatedRig, **kwargs: object) -> BridgeAmplifier:
    kwargs.setdefault("timeout_s", 1.0)
    return BridgeAmplifier(rig.addresses.serial_port, **kwargs)


def test_identity_and_power_on_status(rig: SimulatedRig) -> None:
    a = rig.config.world.amplifier
    with amplifier(rig) as amp:
        assert amp.identity() == a.identity
        status = amp.status()
    assert (status.gain, status.excitation_v, status.lowpass_hz) == (a.gain, a.excitation_v, a.lowpass_hz)
    assert status.shunt_on is False and status.overloaded is False
    assert status.output_v == pytest.approx(a.gain * rig.config.world.accelerometer.bridge_offset_v, abs=1e-4)


def test_settings_round_trip_and_reach_the_world(rig: SimulatedRig) -> None:
    with amplifier(rig) as amp:
        amp.set_excitation_v(2.5)
        amp.set_gain(100)
        amp.set_lowpass_hz(50_000)
        assert (amp.excitation_v(), amp.gain(), amp.lowpass_hz()) == (2.5, 100.0, 50_000.0)
        amp.set_lowpass_hz(0)
        assert amp.lowpass_hz() == 0.0
        amp.configure(gain=20, excitation_v=10.0, lowpass_hz=100_000)
    state = rig.world.amp_settings()
    assert (state.gain, state.excitation_v, state.lowpass_hz) == (20.0, 10.0, 100_000.0)


def test_invalid_settings_are_refused_before_sending(rig: SimulatedRig) -> None:
    with amplifier(rig) as amp:
        served = rig.amplifier.lines_served
        with pytest.raises(ValueError, match="gain 3 not one of"):
            amp.set_gain(3)
        with pytest.raises(ValueError, match="excitation 12 V"):
            amp.set_excitation_v(12)
        with pytest.raises(ValueError, match="low-pass 30000 Hz"):
            amp.set_lowpass_hz(30_000)
        assert rig.amplifier.lines_served == served
        with pytest.raises(InstrumentError, match="amplifier refused: RANGE"):
            amp.query("GAIN 3")  # the device refuses it too
        with pytest.raises(InstrumentError, match="amplifier refused: UNKNOWN"):
            amp.query("FOO?")


def test_auto_zero_and_shunt_calibration_move_the_output_as_the_bridge_does(rig: SimulatedRig) -> None:
    acc = rig.config.world.accelerometer
    with amplifier(rig) as amp:
        amp.configure(gain=20, excitation_v=2.5, lowpass_hz=200_000)
        assert amp.output_v() == pytest.approx(20 * acc.bridge_offset_v, abs=1e-4)
        amp.auto_zero()
        assert amp.output_v() == pytest.approx(0.0, abs=1e-4)
        amp.set_shunt(True)
        assert amp.shunt() is True
        shunt_v = 20 * acc.sensitivity_v_per_m_s2 * (2.5 / acc.nominal_excitation_v) * acc.shunt_equivalent_m_s2
        assert amp.output_v() == pytest.approx(shunt_v, abs=1e-4)
        amp.set_shunt(False)
        assert amp.shunt() is False and amp.output_v() == pytest.approx(0.0, abs=1e-4)


def test_overload_latches_and_clears(rig: SimulatedRig) -> None:
    with amplifier(rig) as amp:
        amp.set_gain(1000)
        amp.set_shunt(True)  # 1000 x 49 mV: far past the 10 V output limit
        assert amp.output_v() == pytest.approx(rig.config.world.amplifier.output_limit_v)
        amp.set_shunt(False)
        assert amp.overloaded() is True  # latched after the cause is gone
        amp.clear_overload()
        assert amp.overloaded() is False


def test_the_device_rejects_a_line_with_a_wrong_checksum(rig: SimulatedRig) -> None:
    with serial.Serial(rig.addresses.serial_port, 115200, timeout=1.0) as port:
        port.write(b"GAIN?*00\n")
        assert parse_line(port.read_until(b"\n")) == "GAIN ERR CHECKSUM"
        port.write(b"GAIN?\r\n")  # no checksum: accepted from a person at a terminal
        assert parse_line(port.read_until(b"\n")) == "GAIN 10"
