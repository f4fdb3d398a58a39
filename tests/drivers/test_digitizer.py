"""The digitizer driver against the simulated SCPI server over the real protocol on loopback
(pyvisa + pyvisa-py, raw TCP socket), plus byte-level tests of the SCPI path against a
scripted socket server that sends exactly the bytes a test chooses."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from hopkinson.drivers.digitizer import BLOCK_CHUNK_BYTES, Digitizer
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.scpi_dialect import GenericScpiDialect, ReplyFormatError
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.scpi_digitizer import AcquisitionSettings, SimDigitizerServer

N_SMALL = 40_000


def synthetic_volts(settings: AcquisitionSettings) -> dict[int, np.ndarray]:
    """Channel 1: a sine near full scale; channel 2: a ramp over the whole range plus a small
    sine, so its int16 codes hold many 0x0A bytes."""
    n = settings.record_length
    t = np.arange(n)
    r1, r2 = settings.ch_range_v[1], settings.ch_range_v[2]
    return {
        1: 0.9 * r1 * np.sin(2 * np.pi * t / 997.0),
        2: np.linspace(-r2, r2, n) * 0.95 + 0.02 * r2 * np.sin(2 * np.pi * t / 50.0),
    }


class World:
    """A capture function that triggers only after `fire()`; records the settings it saw."""

    def __init__(self) -> None:
        self.fired = threading.Event()
        self.seen: list[AcquisitionSettings] = []

    def fire(self) -> None:
        self.fired.set()

    def __call__(self, settings: AcquisitionSettings) -> dict[int, np.ndarray] | None:
        self.seen.append(settings)
        return synthetic_volts(settings) if self.fired.is_set() else None


def _threads() -> set[threading.Thread]:
    return set(threading.enumerate())


@pytest.fixture
def world() -> World:
    return World()


@pytest.fixture
def faults() -> FaultSet:
    return FaultSet()


@pytest.fixture
def server(world: World, faults: FaultSet) -> Iterator[SimDigitizerServer]:
    before = _threads()
    srv = SimDigitizerServer(world, faults)
    srv.start()
    yield srv
    srv.stop()
    assert _threads() <= before, "the simulated digitizer left a thread behind"


@pytest.fixture
def dig(server: SimDigitizerServer) -> Iterator[Digitizer]:
    with Digitizer(server.resource, timeout_s=2.0, name="test digitizer") as d:
        yield d


def _expected_codes(volts: np.ndarray, range_v: float) -> np.ndarray:
    return np.clip(np.rint(volts / (range_v / 32767)), -32768, 32767).astype(np.int16)


# -- identity, settings ---------------------------------------------------------------------


def test_identity(dig: Digitizer) -> None:
    assert dig.identity() == "Hopkinson-Sim,SIMDIG-2CH,SIM0001,1.0"
    assert dig.connected


def test_pyvisa_py_socket_session_receives_in_large_pieces(dig: Digitizer) -> None:
    session = dig._inst.visalib.sessions[dig._inst.session]  # type: ignore[union-attr]
    assert session.max_recv_size == BLOCK_CHUNK_BYTES  # pyvisa-py's stock value is 4096


def test_settings_round_trip_through_the_instrument(dig: Digitizer, server: SimDigitizerServer) -> None:
    dig.set_sample_rate_hz(125e6)
    dig.set_record_length(12_345)
    dig.set_channel_range_v(1, 0.5)
    dig.set_channel_range_v(2, 20.0)
    dig.set_trigger("ch1", -0.25, "neg", 1_000)
    assert dig.sample_rate_hz() == 125e6
    assert dig.record_length() == 12_345
    assert dig.channel_range_v(1) == 0.5
    assert dig.channel_range_v(2) == 20.0
    trig = dig.trigger_settings()
    assert (trig.source, trig.level_v, trig.slope, trig.pre_trigger_samples) == ("CH1", -0.25, "NEG", 1_000)
    held = server.settings  # the instrument's own state, not the driver's echo
    assert held.sample_rate_hz == 125e6 and held.record_length == 12_345
    assert held.ch_range_v == {1: 0.5, 2: 20.0}
    assert (held.trigger_source, held.trigger_level_v, held.trigger_slope) == ("CH1", -0.25, "NEG")
    assert held.pre_trigger_samples == 1_000


def test_configure_takes_the_rig_config_names(dig: Digitizer, server: SimDigitizerServer) -> None:
    dig.configure(
        sample_rate_hz=50e6,
        record_length=20_000,
        pre_trigger_fraction=0.25,
        ch1_range_v=2.0,
        ch2_range_v=5.0,
        trigger_source="CH2",
        trigger_level_v=0.3,
        trigger_slope="POS",
    )
    held = server.settings
    assert held.sample_rate_hz == 50e6 and held.record_length == 20_000
    assert held.pre_trigger_samples == 5_000
    assert held.ch_range_v == {1: 2.0, 2: 5.0}
    assert (held.trigger_source, held.trigger_level_v, held.trigger_slope) == ("CH2", 0.3, "POS")
    dig.configure(trigger_level_v=-0.1)  # partial: the rest stays as the instrument holds it
    assert dig.trigger_settings().level_v == -0.1
    assert server.settings.trigger_source == "CH2" and server.settings.pre_trigger_samples == 5_000


def test_refused_command_names_instrument_command_and_reply(dig: Digitizer) -> None:
    dig.set_record_length(1_000)
    with pytest.raises(InstrumentError) as info:
        dig.set_trigger("CH2", 0.1, "POS", 1_000)  # pre-trigger must be below the record length
    err = info.value
    assert err.instrument == dig.instrument and "test digitizer" in str(err)
    assert ":ACQuire:PRETrigger 1000" in err.command
    assert err.reply.startswith("-221,")
    assert dig.connected  # a refusal is not a transport failure
    with pytest.raises(InstrumentError, match="error -222"):
        dig.set_sample_rate_hz(1e12)  # beyond the instrument's limit
    dig.set_sample_rate_hz(10e6)  # the error queue does not leak into the next command


@pytest.mark.parametrize(
    "call",
    [
        lambda d: d.set_sample_rate_hz(-1.0),
        lambda d: d.set_sample_rate_hz(float("nan")),
        lambda d: d.set_record_length(0),
        lambda d: d.set_record_length(10.5),
        lambda d: d.set_channel_range_v(3, 1.0),
        lambda d: d.set_channel_range_v(1, 0.0),
        lambda d: d.set_trigger("CH3", 0.1, "POS", 10),
        lambda d: d.set_trigger("CH1", 0.1, "UP", 10),
        lambda d: d.set_trigger("CH1", float("inf"), "POS", 10),
        lambda d: d.set_trigger("CH1", 0.1, "POS", -1),
        lambda d: d.fetch_waveform(0),
        lambda d: d.configure(pre_trigger_fraction=1.5),
    ],
)
def test_invalid_arguments_are_refused_before_sending(
    dig: Digitizer, server: SimDigitizerServer, call: Callable[[Digitizer], object]
) -> None:
    before = server.settings
    with pytest.raises(InstrumentError, match="test digitizer"):
        call(dig)
    assert server.settings == before
    assert dig.connected


def test_settings_are_refused_while_armed(dig: Digitizer) -> None:
    dig.arm_single()
    with pytest.raises(InstrumentError, match="-221"):
        dig.set_record_length(1_000)


# -- acquisition ----------------------------------------------------------------------------


def test_arm_wait_trigger_fetch(dig: Digitizer, world: World) -> None:
    dig.configure(
        sample_rate_hz=100e6, record_length=N_SMALL, pre_trigger_samples=4_000, ch1_range_v=1.0, ch2_range_v=10.0
    )
    assert dig.acquisition_state() == "IDLE"
    dig.arm_single()
    assert dig.acquisition_state() == "ARMED"
    assert dig.wait_for_trigger(timeout_s=0.05) is False  # the world has not fired
    assert dig.acquisition_state() == "ARMED"
    world.fire()
    assert dig.wait_for_trigger(timeout_s=1.0) is True
    assert dig.acquisition_state() == "TRIGGERED"
    assert world.seen[-1].record_length == N_SMALL and world.seen[-1].pre_trigger_samples == 4_000

    truth = synthetic_volts(world.seen[-1])
    for channel, range_v in ((1, 1.0), (2, 10.0)):
        wave = dig.fetch_waveform(channel)
        assert wave.channel == channel and wave.codes.dtype == np.int16 and wave.codes.size == N_SMALL
        np.testing.assert_array_equal(wave.codes, _expected_codes(truth[channel], range_v))
        lsb_v = range_v / 32767
        assert wave.scale_v == pytest.approx(lsb_v, rel=1e-12) and wave.offset_v == 0.0
        assert np.max(np.abs(wave.volts() - truth[channel])) <= 0.5 * lsb_v * (1 + 1e-9)
        assert wave.sample_interval_s == pytest.approx(1e-8, rel=1e-12)
        assert wave.sample_rate_hz == pytest.approx(100e6)
        assert wave.trigger_index == 4_000 and wave.time_s()[4_000] == 0.0
    assert wave.codes.tobytes().count(b"\n") > 100  # channel 2's block carried many 0x0A bytes


def test_block_read_does_not_stop_at_0x0a(dig: Digitizer, world: World, monkeypatch: pytest.MonkeyPatch) -> None:
    n = 300_000
    dig.configure(record_length=n, pre_trigger_samples=0)
    world.fire()
    dig.arm_single()
    assert dig.wait_for_trigger(1.0)
    visalib = dig._inst.visalib  # type: ignore[union-attr]
    calls: list[int] = []
    real_read = visalib.read

    def counting_read(session: object, count: int) -> object:
        calls.append(count)
        return real_read(session, count)

    monkeypatch.setattr(visalib, "read", counting_read)
    wave = dig.fetch_waveform(2)
    newlines = wave.codes.tobytes().count(b"\n")
    assert newlines > 2_000
    # preamble reply + block header + 2 * n bytes in BLOCK_CHUNK_BYTES reads (a few spare);
    # a read that stopped at every 0x0A would need more calls than there are newlines
    assert len(calls) <= 4 + 2 * n // BLOCK_CHUNK_BYTES + 4 < newlines


def test_wait_for_trigger_when_not_armed_raises(dig: Digitizer) -> None:
    with pytest.raises(InstrumentError, match="not armed"):
        dig.wait_for_trigger(timeout_s=0.1)


def test_fetch_without_acquisition_is_a_clear_error(dig: Digitizer) -> None:
    with pytest.raises(InstrumentError, match="no acquired record on channel 1") as info:
        dig.fetch_waveform(1)
    assert info.value.reply.startswith("INT16,LSBF,0,")
    dig.identity()  # the session is still in step


def test_abort_disarms_and_discards(dig: Digitizer, world: World) -> None:
    dig.set_record_length(1_000)
    world.fire()
    dig.arm_single()
    assert dig.wait_for_trigger(1.0)
    dig.abort()
    assert dig.acquisition_state() == "IDLE"
    with pytest.raises(InstrumentError, match="no acquired record"):
        dig.fetch_waveform(2)


# -- faults, dropped links, connection life cycle -------------------------------------------


def test_garbled_block_is_a_clear_error_and_the_link_recovers(
    dig: Digitizer, world: World, faults: FaultSet
) -> None:
    dig.set_record_length(N_SMALL)
    world.fire()
    dig.arm_single()
    assert dig.wait_for_trigger(1.0)
    faults.inject("visa-garbled-block")
    with pytest.raises(InstrumentError, match="garbled binary block") as info:
        dig.fetch_waveform(2)
    assert info.value.instrument == dig.instrument
    assert info.value.command == ":WAVeform:DATA?"
    assert "not decimal digits" in info.value.problem
    assert not dig.connected  # the rest of the payload is still in the stream: session closed
    with pytest.raises(InstrumentConnectionError, match="not connected"):
        dig.identity()
    faults.clear("visa-garbled-block")
    dig.connect()
    wave = dig.fetch_waveform(2)  # the record survived on the instrument
    np.testing.assert_array_equal(wave.codes, _expected_codes(synthetic_volts(world.seen[-1])[2], 10.0))


def test_dropped_connection_is_reported_and_reconnect_works(server: SimDigitizerServer) -> None:
    with Digitizer(server.resource, timeout_s=0.3) as d:
        assert server.drop_connections() == 1
        with pytest.raises(InstrumentError) as info:
            d.identity()
        assert isinstance(info.value, InstrumentTimeout | InstrumentConnectionError)
        assert "*IDN?" in str(info.value) and server.resource in str(info.value)
        assert not d.connected
        d.connect()
        assert d.identity().startswith("Hopkinson-Sim")


def test_nothing_listening_is_a_connection_error() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    resource = f"TCPIP0::127.0.0.1::{port}::SOCKET"
    with pytest.raises(InstrumentConnectionError, match=f"digitizer \\({resource}\\)"):
        Digitizer(resource, timeout_s=0.5).connect()
    with pytest.raises(InstrumentConnectionError, match="cannot open"):
        Digitizer("TCPIP0::127.0.0.1::notaport::SOCKET", timeout_s=0.5).connect()


def test_context_manager_always_disconnects(server: SimDigitizerServer) -> None:
    d = Digitizer(server.resource, timeout_s=1.0)
    with pytest.raises(RuntimeError, match="boom"), d:
        assert d.connected
        raise RuntimeError("boom")
    assert not d.connected
    deadline = time.monotonic() + 2.0  # the server sees the client go and ends its thread
    while server._server._clients and time.monotonic() < deadline:  # type: ignore[union-attr]
        time.sleep(0.01)
    assert not server._server._clients  # type: ignore[union-attr]


def test_server_stops_cleanly_with_clients_connected_mid_transfer(world: World) -> None:
    before = _threads()
    srv = SimDigitizerServer(world, FaultSet())
    srv.start()
    assert srv.port > 0 and srv.resource == f"TCPIP0::127.0.0.1::{srv.port}::SOCKET"
    idle = Digitizer(srv.resource, timeout_s=1.0)
    idle.connect()  # left connected: stop() must still end its handler
    world.fire()
    stuck = socket.create_connection(("127.0.0.1", srv.port))
    stuck.sendall(b":ACQ:POIN 5000000;:SING;:ACQ:STAT?\n:WAV:DATA?\n")  # 10 MB never read
    time.sleep(0.2)
    srv.stop()
    srv.stop()  # idempotent
    stuck.close()
    idle.close()
    assert _threads() <= before
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", srv.port), timeout=0.5).close()


def test_two_servers_get_distinct_free_ports(world: World) -> None:
    with SimDigitizerServer(world, FaultSet()) as a, SimDigitizerServer(world, FaultSet()) as b:
        assert a.port != b.port
        for srv in (a, b):
            with Digitizer(srv.resource, timeout_s=1.0) as d:
                assert d.identity().startswith("Hopkinson-Sim")


def test_timeout_must_be_positive() -> None:
    with pytest.raises(ValueError, match="timeout_s"):
        Digitizer("TCPIP0::127.0.0.1::1::SOCKET", timeout_s=0)


# -- byte-level SCPI path against a scripted server -----------------------------------------


class ScriptedServer:
    """Accepts one connection; answers each received line with the bytes scripted for it
    (or nothing); records what the client sent. After `close_after`, drops the link."""

    def __init__(self, script: dict[str, bytes]) -> None:
        self.script = script
        self.received: list[str] = []
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self.resource = f"TCPIP0::127.0.0.1::{self.port}::SOCKET"
        self._thread = threading.Thread(target=self._serve)
        self._thread.start()

    def _serve(self) -> None:
        try:
            conn, _ = self._listener.accept()
        except OSError:
            return
        with conn:
            buffer = b""
            while True:
                try:
                    data = conn.recv(65536)
                except OSError:
                    return
                if not data:
                    return
                buffer += data
                while b"\n" in buffer:
                    line, buffer = buffer.split(b"\n", 1)
                    text = line.decode()
                    self.received.append(text)
                    reply = self.script.get(text)
                    if reply is None and text.endswith(":SYSTem:ERRor?"):
                        reply = b'0,"No error"\n'
                    if reply == b"<drop>":
                        return
                    if reply:
                        conn.sendall(reply)

    def close(self) -> None:
        self._listener.close()
        with socket.socket() as poke:  # unblock accept() if nobody connected
            poke.settimeout(0.2)
            try:
                poke.connect(("127.0.0.1", self.port))
            except OSError:
                pass
        self._thread.join(timeout=5)
        assert not self._thread.is_alive()


@pytest.fixture
def scripted() -> Iterator[Callable[[dict[str, bytes]], ScriptedServer]]:
    servers: list[ScriptedServer] = []

    def make(script: dict[str, bytes]) -> ScriptedServer:
        base = {"*IDN?": b"ACME,SCRIPT,1,1\n"}
        srv = ScriptedServer(base | script)
        servers.append(srv)
        return srv

    yield make
    for srv in servers:
        srv.close()


PRE = ":WAVeform:SOURce CH1;:WAVeform:PREamble?"


def test_exact_bytes_on_the_wire_and_a_0x0a_block_big_endian(scripted: Callable[..., ScriptedServer]) -> None:
    codes = np.array([10, 0x0A0A, -246, 2560, 32767, -32768], dtype=">i2")  # 0x0A bytes everywhere
    raw = codes.tobytes()
    assert raw.count(b"\n") >= 4
    srv = scripted(
        {
            PRE: b"INT16,MSBF,6,2.5e-07,2,0.001,-0.5\n",
            ":WAVeform:DATA?": b"#212" + raw + b"\n",
        }
    )
    with Digitizer(srv.resource, timeout_s=1.0) as d:
        wave = d.fetch_waveform(1)
        assert d.identity() == "ACME,SCRIPT,1,1"  # the stream is in step after the block
    np.testing.assert_array_equal(wave.codes, codes.astype(np.int16))
    np.testing.assert_allclose(wave.volts(), codes * 0.001 - 0.5)
    assert (wave.sample_interval_s, wave.trigger_index) == (2.5e-07, 2)
    assert srv.received == ["*IDN?", "*CLS", PRE, ":WAVeform:DATA?", "*IDN?"]


def test_setting_is_sent_with_the_error_query_in_one_message(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({})
    with Digitizer(srv.resource, timeout_s=1.0) as d:
        d.set_sample_rate_hz(2.5e8)
        d.set_trigger("EXT", 1.5, "NEG", 7)
    assert srv.received[2] == "*CLS;:ACQuire:SRATe 250000000.0;:SYSTem:ERRor?"
    assert srv.received[3] == (
        "*CLS;:TRIGger:SOURce EXT;:TRIGger:LEVel 1.5;:TRIGger:SLOPe NEG;:ACQuire:PRETrigger 7;:SYSTem:ERRor?"
    )


def test_truncated_block_then_silence_is_a_timeout(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,500,1e-08,0,0.001,0.0\n", ":WAVeform:DATA?": b"#41000" + b"\n" * 10})
    with Digitizer(srv.resource, timeout_s=0.3) as d:
        with pytest.raises(InstrumentTimeout, match=r"':WAVeform:DATA\?'.*no complete reply within 0.3 s"):
            d.fetch_waveform(1)
        assert not d.connected


def test_block_shorter_than_the_preamble_says(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,500,1e-08,0,0.001,0.0\n", ":WAVeform:DATA?": b"#18\n\n\n\n\n\n\n\n\n"})
    with Digitizer(srv.resource, timeout_s=1.0) as d:
        with pytest.raises(InstrumentError, match="block has 8 bytes, the preamble announced 500"):
            d.fetch_waveform(1)


def test_block_without_its_terminator(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,2,1e-08,0,0.001,0.0\n", ":WAVeform:DATA?": b"#14\n\n\n\nX"})
    with Digitizer(srv.resource, timeout_s=1.0) as d:
        with pytest.raises(InstrumentError, match="garbled binary block.*terminator"):
            d.fetch_waveform(1)


@pytest.mark.parametrize(
    ("reply", "words"),
    [
        (b"INT16,LSBF,5\n", "3 fields"),
        (b"FLOAT32,LSBF,5,1e-8,0,1,0\n", "unsupported sample format"),
        (b"INT16,LSBF,five,1e-8,0,1,0\n", "non-numeric"),
        (b"INT16,LSBF,5,0,0,1,0\n", "out of range"),
    ],
)
def test_bad_preamble_names_command_and_reply(
    scripted: Callable[..., ScriptedServer], reply: bytes, words: str
) -> None:
    srv = scripted({PRE: reply})
    with Digitizer(srv.resource, timeout_s=1.0) as d:
        with pytest.raises(InstrumentError, match=words) as info:
            d.fetch_waveform(1)
    assert info.value.command == PRE and info.value.reply == reply.decode().strip()


def test_unexpected_state_and_number_replies(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted(
        {":ACQuire:STATe?": b"RUNNING\n", ":ACQuire:SRATe?": b"fast\n", ":ACQuire:POINts?": b"\xff\xfe12\n"}
    )
    with Digitizer(srv.resource, timeout_s=1.0) as d:
        with pytest.raises(InstrumentError, match="unknown acquisition state") as info:
            d.acquisition_state()
        assert info.value.reply == "RUNNING"
        with pytest.raises(InstrumentError, match="expected a number"):
            d.sample_rate_hz()
        with pytest.raises(InstrumentError, match="not ASCII text") as info:
            d.record_length()
        assert "\\xff\\xfe12" in info.value.reply


def test_link_dropped_mid_block(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,500,1e-08,0,0.001,0.0\n", ":WAVeform:DATA?": b"<drop>"})
    with Digitizer(srv.resource, timeout_s=0.3) as d:
        with pytest.raises(InstrumentError, match="DATA"):
            d.fetch_waveform(1)
        assert not d.connected


class VendorBDialect(GenericScpiDialect):
    """A second vendor: different arm command and state words; the driver is unchanged."""

    name = "vendor-b"
    arm_single = ":DIGitize:SINGle"
    state_query = ":DIGitize:STATus?"

    def parse_state(self, reply: str) -> str:
        words = {"STOP": "IDLE", "WAIT": "ARMED", "DONE": "TRIGGERED"}
        if reply.strip() not in words:
            raise ReplyFormatError(f"unknown acquisition state {reply!r}")
        return words[reply.strip()]


def test_a_second_vendor_is_one_dialect_class(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({":DIGitize:STATus?": b"DONE\n"})
    with Digitizer(srv.resource, timeout_s=1.0, dialect=VendorBDialect()) as d:
        d.arm_single()
        assert d.wait_for_trigger(timeout_s=0.5)
    assert "*CLS;:DIGitize:SINGle;:SYSTem:ERRor?" in srv.received


def test_dialect_parses_error_queue_replies() -> None:
    dialect = GenericScpiDialect()
    assert dialect.parse_error('0,"No error"') == (0, "No error")
    assert dialect.parse_error('-222,"Data out of range; :ACQ:SRAT 1e12"') == (-222, "Data out of range; :ACQ:SRAT 1e12")
    with pytest.raises(ReplyFormatError):
        dialect.parse_error("OK")


def test_transfer_benchmark_smoke() -> None:
    """The benchmark runs end to end on a small record; it checks itself that the three
    readers return the same samples, and ends with one JSON line."""
    script = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_transfer.py"
    out = subprocess.run(
        [sys.executable, str(script), "--samples", "200000", "--repeats", "1", "--default-repeats", "1"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout
    result = json.loads(out.strip().splitlines()[-1])
    assert result["bytes"] == 400_000 and result["newline_bytes"] > 100
    for key in ("raw_socket_mb_s", "driver_mb_s", "driver_4k_recv_mb_s", "pyvisa_default_mb_s"):
        assert result[key] > 0
