"""The digitizer driver's own behaviour (generic dialect) against the simulated SCPI server over
loopback (pyvisa + pyvisa-py, raw TCP socket), plus byte-level tests of the VISA path against a
scripted socket server that sends exactly the bytes a test chooses: framing, garbled and
truncated blocks, and bounded reads (an endless or oversized reply is an error naming the
instrument and the command, within the timeout)."""

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

from hopkinson.drivers.base import TraceRecord
from hopkinson.drivers.digitizer import Digitizer
from hopkinson.drivers.digitizer_settings import DigitizerSettings
from hopkinson.drivers.digitizer_visa import _SocketReader
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.scpi_digitizer import SimDigitizerServer
from tests.drivers.digitizer_world import World, expected_codes

N_SMALL = 20_000


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
    with Digitizer(server.resource, timeout_s=2.0, name="test digitizer",
                   channels={"doppler": "CH1", "response": "CH2"}) as d:
        yield d


def settings(**changes: object) -> DigitizerSettings:
    base = DigitizerSettings(sample_rate_hz=100e6, record_length=N_SMALL, pre_trigger_samples=2_000,
                             ranges_v={"CH1": 1.0, "CH2": 10.0}, trigger_source="CH2", trigger_level_v=0.5,
                             trigger_slope="POS")
    return base.with_changes(**changes)


def capture(dig: Digitizer, world: World) -> None:
    dig.arm_single()
    world.fire()
    assert dig.wait_for_trigger(2.0)


# -- identity, settings ---------------------------------------------------------------------


def test_identity(dig: Digitizer) -> None:
    assert dig.identity() == "Hopkinson-Sim,SIMDIG-4CH,SIM0001,1.0"


def test_older_keyword_configure_still_works(dig: Digitizer, server: SimDigitizerServer) -> None:
    dig.configure(sample_rate_hz=50e6, record_length=20_000, pre_trigger_fraction=0.25, ch1_range_v=2.0,
                  ch2_range_v=5.0, trigger_source="ch2", trigger_level_v=0.3, trigger_slope="pos")
    held = server.settings
    assert (held.sample_rate_hz, held.record_length, held.pre_trigger_samples) == (50e6, 20_000, 5_000)
    assert (held.ch_range_v[1], held.ch_range_v[2]) == (2.0, 5.0)
    assert (held.trigger_source, held.trigger_level_v, held.trigger_slope) == ("CH2", 0.3, "POS")
    dig.configure(trigger_level_v=-0.1)  # partial: the rest stays as the instrument holds it
    assert server.settings.trigger_level_v == -0.1 and server.settings.pre_trigger_samples == 5_000
    assert dig.channel_range_v("response") == 5.0 and dig.channel_range_v(1) == 2.0


@pytest.mark.parametrize(
    "changes",
    [
        {"sample_rate_hz": -1.0},
        {"sample_rate_hz": float("nan")},
        {"record_length": 0},
        {"pre_trigger_samples": N_SMALL},
        {"ranges_v": {"CH1": 0.0}},
        {"ranges_v": {"CH9": 1.0}},
        {"trigger_source": "CH7"},
        {"trigger_slope": "UP"},
        {"trigger_level_v": float("inf")},
    ],
)
def test_invalid_settings_are_refused_before_sending(dig: Digitizer, server: SimDigitizerServer,
                                                     changes: dict[str, object]) -> None:
    before = server.settings
    with pytest.raises(InstrumentError, match="test digitizer") as info:
        dig.configure(settings(**changes))
    assert info.value.command == "configure"
    assert server.settings == before
    assert dig.connected


def test_channels_by_role_name_or_number(dig: Digitizer, world: World) -> None:
    dig.configure(settings())
    capture(dig, world)
    by_role = dig.fetch_waveform("response")
    assert by_role.channel == "CH2"
    np.testing.assert_array_equal(dig.fetch_waveform("ch2").codes, by_role.codes)
    np.testing.assert_array_equal(dig.fetch_waveform(2).codes, by_role.codes)
    with pytest.raises(InstrumentError, match="roles: doppler, response"):
        dig.fetch_waveform("doppler_quadrature")


def test_arm_wait_trigger_fetch(dig: Digitizer, world: World) -> None:
    dig.configure(settings())
    assert dig.acquisition_state() == "IDLE"
    dig.arm_single()
    assert dig.acquisition_state() == "ARMED"
    assert dig.wait_for_trigger(timeout_s=0.05) is False  # the world has not fired
    world.fire()
    assert dig.wait_for_trigger(timeout_s=1.0) is True
    truth = world.record(world.seen[-1])
    blocks = b""
    for role, ch, range_v in (("doppler", 1, 1.0), ("response", 2, 10.0)):
        wave = dig.fetch_waveform(role)
        blocks += wave.codes.tobytes()
        np.testing.assert_array_equal(wave.codes, expected_codes(truth[ch], range_v, "int16"))
        assert wave.sample_interval_s == pytest.approx(1e-8, rel=1e-12)
        assert wave.trigger_index == 2_000 and wave.time_s()[2_000] == 0.0
        assert wave.code_range == (-32768.0, 32767.0)
    assert blocks.count(b"\n") > 10  # the blocks carried 0x0A bytes


def test_block_read_does_not_stop_at_0x0a(dig: Digitizer, world: World, monkeypatch: pytest.MonkeyPatch) -> None:
    n = 300_000
    dig.configure(settings(record_length=n, pre_trigger_samples=1_000, ranges_v={"CH1": 1.0, "CH2": 0.5}))
    capture(dig, world)
    calls: list[int] = []
    real_read_into = _SocketReader.read_into

    def counting_read_into(self: _SocketReader, view: memoryview, wait_s: float) -> int:
        calls.append(len(view))
        return real_read_into(self, view, wait_s)

    monkeypatch.setattr(_SocketReader, "read_into", counting_read_into)
    wave = dig.fetch_waveform("doppler")
    newlines = wave.codes.tobytes().count(b"\n")
    assert newlines > 500
    # the block header, then 2 * n bytes in pieces of up to BLOCK_CHUNK_BYTES (as the socket
    # delivers them); a read that stopped at every 0x0A would need more calls than there are newlines
    assert len(calls) < newlines / 4


def test_wait_for_trigger_when_not_armed_raises(dig: Digitizer) -> None:
    with pytest.raises(InstrumentError, match="not armed"):
        dig.wait_for_trigger(timeout_s=0.1)


def test_abort_disarms_and_discards(dig: Digitizer, world: World) -> None:
    dig.configure(settings())
    capture(dig, world)
    dig.abort()
    assert dig.acquisition_state() == "IDLE"
    with pytest.raises(InstrumentError, match="no acquired record"):
        dig.fetch_waveform("response")


def test_trace_hook_sees_every_exchange_with_blocks_summarised(dig: Digitizer, world: World) -> None:
    records: list[TraceRecord] = []
    dig.configure(settings())
    capture(dig, world)
    dig.trace = records.append
    dig.fetch_waveform("response")
    texts = [(r.direction, r.text) for r in records]
    assert ("->", ":WAVeform:DATA?") in texts
    assert ("<-", f"<binary block: {2 * N_SMALL} bytes>") in texts
    assert all(r.instrument == dig.instrument and r.utc.endswith("+00:00") for r in records)


# -- faults, dropped links, connection life cycle -------------------------------------------


def test_garbled_block_is_a_clear_error_and_the_link_recovers(dig: Digitizer, world: World, faults: FaultSet) -> None:
    dig.configure(settings())
    capture(dig, world)
    faults.inject("visa-garbled-block")
    with pytest.raises(InstrumentError, match="garbled binary block") as info:
        dig.fetch_waveform("response")
    assert info.value.instrument == dig.instrument and info.value.command == ":WAVeform:DATA?"
    assert not dig.connected  # the rest of the payload is still in the stream: session closed
    faults.clear("visa-garbled-block")
    wave = dig.fetch_waveform("response")  # the next call opens a fresh session; the record survived
    np.testing.assert_array_equal(wave.codes, expected_codes(world.record(world.seen[-1])[2], 10.0, "int16"))


def test_dropped_connection_is_reported_and_the_next_call_reconnects(server: SimDigitizerServer) -> None:
    with Digitizer(server.resource, timeout_s=0.3) as d:
        assert server.drop_connections() == 1
        with pytest.raises(InstrumentError) as info:
            d.identity()
        assert isinstance(info.value, InstrumentTimeout | InstrumentConnectionError)
        assert "*IDN?" in str(info.value) and server.resource in str(info.value)
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


def test_visa_library_and_terminations_are_configurable(server: SimDigitizerServer, tmp_path: Path) -> None:
    with Digitizer(server.resource, timeout_s=1.0, visa_library="@py", write_termination="\r\n") as d:
        assert d.identity().startswith("Hopkinson-Sim")
    missing = tmp_path / "libvisa-missing.so"
    with pytest.raises(InstrumentConnectionError, match="cannot load the VISA library") as info:
        Digitizer(server.resource, visa_library=str(missing)).connect()
    assert str(missing) in str(info.value)


def test_context_manager_always_disconnects(server: SimDigitizerServer) -> None:
    d = Digitizer(server.resource, timeout_s=1.0)
    with pytest.raises(RuntimeError, match="boom"), d:
        assert d.connected
        raise RuntimeError("boom")
    assert not d.connected
    with pytest.raises(InstrumentConnectionError, match="not connected"):
        d.identity()  # closed on purpose: not reopened behind the caller's back


def test_server_stops_cleanly_with_clients_connected_mid_transfer(world: World) -> None:
    before = _threads()
    srv = SimDigitizerServer(world, FaultSet())
    srv.start()
    idle = Digitizer(srv.resource, timeout_s=1.0)
    idle.connect()  # left connected: stop() must still end its handler
    stuck = socket.create_connection(("127.0.0.1", srv.port))
    stuck.sendall(b":ACQ:POIN 2000000;:ACQ:PRET 1000;:TRIG:LEV 0.5;:SING\n")
    world.fire()
    stuck.sendall(b":WAV:DATA?\n*OPC?\n")  # 4 MB never read
    time.sleep(0.2)
    blocked = socket.create_connection(("127.0.0.1", srv.port))
    blocked.sendall(b":SING\n*OPC?\n")  # waits for an acquisition that never comes
    time.sleep(0.1)
    srv.stop()
    srv.stop()  # idempotent
    for sock in (stuck, blocked):
        sock.close()
    idle.close()
    assert _threads() <= before
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", srv.port), timeout=0.5).close()


# -- byte-level VISA path against a scripted server ------------------------------------------


class ScriptedServer:
    """Accepts one connection; answers each received line with the bytes scripted for it (a
    callable may stream); records what the client sent."""

    def __init__(self, script: dict[str, bytes | Callable[[socket.socket], None]]) -> None:
        self.script = script
        self.received: list[str] = []
        self.stop = threading.Event()
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
            while not self.stop.is_set():
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
                    try:
                        if callable(reply):
                            reply(conn)
                        elif reply == b"<drop>":
                            return
                        elif reply:
                            conn.sendall(reply)
                    except OSError:
                        return

    def close(self) -> None:
        self.stop.set()
        self._listener.close()
        with socket.socket() as poke:  # unblock accept() if nobody connected
            poke.settimeout(0.2)
            try:
                poke.connect(("127.0.0.1", self.port))
            except OSError:
                pass
        self._thread.join(timeout=5)
        assert not self._thread.is_alive()


PREPARE = "*CLS;:WAVeform:FORMat INT16;:WAVeform:BYTeorder LSBF;:SYSTem:ERRor?"
PRE = ":WAVeform:SOURce CH1;:WAVeform:PREamble?;:CHANnel1:RANGe?"


@pytest.fixture
def scripted() -> Iterator[Callable[[dict], ScriptedServer]]:
    servers: list[ScriptedServer] = []

    def make(script: dict) -> ScriptedServer:
        srv = ScriptedServer({"*IDN?": b"ACME,SCRIPT,1,1\n"} | script)
        servers.append(srv)
        return srv

    yield make
    for srv in servers:
        srv.close()


def connected(srv: ScriptedServer, timeout_s: float = 1.0, **kw: object) -> Digitizer:
    """A driver for the scripted server (connects in `with`), configured for a 6-sample record."""
    d = Digitizer(srv.resource, timeout_s=timeout_s, **kw)  # type: ignore[arg-type]
    d._context = settings(record_length=6, pre_trigger_samples=2)
    return d


def test_exact_bytes_on_the_wire_and_a_0x0a_block_big_endian(scripted: Callable[..., ScriptedServer]) -> None:
    codes = np.array([10, 0x0A0A, -246, 2560, 32767, -32768], dtype=">i2")  # 0x0A bytes everywhere
    raw = codes.tobytes()
    assert raw.count(b"\n") >= 4
    srv = scripted({PRE: b"INT16,MSBF,6,2.5e-07,2,0.001,-0.5;32.767\n", ":WAVeform:DATA?": b"#212" + raw + b"\n"})
    with connected(srv) as d:
        wave = d.fetch_waveform(1)
        assert d.identity() == "ACME,SCRIPT,1,1"  # the stream is in step after the block
    np.testing.assert_array_equal(wave.codes, codes.astype(np.int16))
    np.testing.assert_allclose(wave.volts(), codes * 0.001 - 0.5)
    assert (wave.sample_interval_s, wave.trigger_index) == (2.5e-07, 2)
    assert wave.clipped_samples() == 2  # 32767 and -32768: the format's rails
    assert srv.received == ["*IDN?", PREPARE, PRE, ":WAVeform:DATA?", "*IDN?"]


def test_unsigned_codes_are_never_wrapped(scripted: Callable[..., ScriptedServer]) -> None:
    codes = np.array([40000, 0, 65535, 32768, 1, 2], dtype="<u2")
    srv = scripted({PRE: b"UINT16,LSBF,6,1e-08,0,0.0003,-9.8304;10\n",
                    ":WAVeform:DATA?": b"#212" + codes.tobytes() + b"\n"})
    with connected(srv) as d:
        wave = d.fetch_waveform(1)
    assert wave.codes.dtype == np.uint16 and wave.codes[0] == 40000
    assert wave.volts()[0] == pytest.approx(40000 * 0.0003 - 9.8304)
    assert wave.code_range == (0.0, 65535.0) and wave.clipped_samples() == 2


def test_a_float_sample_that_is_not_a_number_is_an_error(scripted: Callable[..., ScriptedServer]) -> None:
    samples = np.array([0.1, np.nan, 0.2, 0.0, 0.0, 0.0], dtype="<f4")
    srv = scripted({PRE: b"FLOAT32,LSBF,6,1e-08,0,1.0,0.0;1\n",
                    ":WAVeform:DATA?": b"#224" + samples.tobytes() + b"\n"})
    with connected(srv) as d, pytest.raises(InstrumentError, match="not finite numbers.*sample 1") as info:
        d.fetch_waveform(1)
    assert info.value.command == ":WAVeform:DATA?"


def test_setting_is_sent_with_the_error_query_in_one_message(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({})
    with connected(srv) as d:
        d.configure(settings(ranges_v={"CH1": 1.0}, trigger_source="EXT", trigger_level_v=1.5, trigger_slope="NEG",
                             pre_trigger_samples=7, sample_rate_hz=2.5e8))
    assert srv.received[2] == (
        "*CLS;:CHANnel1:DISPlay ON;:ACQuire:SRATe 250000000.0;:ACQuire:POINts 20000;:ACQuire:PRETrigger 7;:CHANnel1:RANGe 1.0;"
        ":TRIGger:SOURce EXT;:TRIGger:LEVel 1.5;:TRIGger:SLOPe NEG;:SYSTem:ERRor?")


@pytest.mark.timeout(60)
def test_a_timeout_names_the_limit_set_not_what_was_left_of_it(scripted: Callable[..., ScriptedServer]) -> None:
    """Half the block's header, a pause of a third of the limit, the rest of the header and half
    the block, then silence: the message names the 0.3 s the instrument was given (it read 0.2 s,
    the time left when the header came, before the block's deadline was the overall one extended)."""
    def header_pause_half(conn: socket.socket) -> None:
        conn.sendall(b"#2")
        time.sleep(0.1)
        conn.sendall(b"12" + b"\x00" * 6)

    srv = scripted({PRE: b"INT16,LSBF,6,1e-08,0,0.001,0.0;1\n", ":WAVeform:DATA?": header_pause_half})
    with connected(srv, timeout_s=0.3) as d:
        with pytest.raises(InstrumentTimeout, match=r"no complete reply within 0.3 s \(6 of 13 bytes came\)"):
            d.fetch_waveform(1)


@pytest.mark.timeout(60)  # a driver waiting forever fails here (the reply never completes)
def test_truncated_block_then_silence_is_a_timeout(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,6,1e-08,0,0.001,0.0;1\n", ":WAVeform:DATA?": b"#212" + b"\n" * 5})
    with connected(srv, timeout_s=0.3) as d:
        with pytest.raises(InstrumentTimeout, match=r"':WAVeform:DATA\?'.*no complete reply within 0.3 s"):
            d.fetch_waveform(1)
        assert not d.connected


def test_block_announcing_more_than_the_record_is_refused_unread(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,6,1e-08,0,0.001,0.0;1\n", ":WAVeform:DATA?": b"#9900000000"})
    with connected(srv) as d, pytest.raises(InstrumentError, match="announces 900000000 bytes.*oversized"):
        d.fetch_waveform(1)


def test_block_shorter_than_the_preamble_says(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,6,1e-08,0,0.001,0.0;1\n", ":WAVeform:DATA?": b"#18\n\n\n\n\n\n\n\n\n"})
    with connected(srv) as d, pytest.raises(InstrumentError, match="block has 8 bytes, the preamble announced 6"):
        d.fetch_waveform(1)


def test_block_without_its_terminator(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,6,1e-08,0,0.001,0.0;1\n", ":WAVeform:DATA?": b"#212" + b"\n" * 12 + b"X"})
    with connected(srv) as d, pytest.raises(InstrumentError, match="garbled binary block.*terminator"):
        d.fetch_waveform(1)


def _endless(conn: socket.socket) -> None:
    """A digitizer streaming its reply without ever sending a newline."""
    chunk = b"1" * 65536
    while True:
        conn.sendall(chunk)


def _trickle(conn: socket.socket) -> None:
    """One byte every 20 ms, never a newline, until the client hangs up: a timeout per read
    would never end it; only a deadline for the whole reply does."""
    while True:
        conn.sendall(b"7")
        time.sleep(0.02)


@pytest.mark.timeout(60)  # both streams go on until the driver hangs up: one that never does fails here
@pytest.mark.parametrize(("stream", "error", "words"), [
    (_endless, InstrumentError, "reply longer than 4096 bytes"),
    (_trickle, InstrumentTimeout, "no complete reply within 0.5 s"),
])
def test_an_endless_or_slow_reply_is_bounded(scripted: Callable[..., ScriptedServer], stream: Callable,
                                             error: type, words: str) -> None:
    srv = scripted({":ACQuire:STATe?": stream})
    with connected(srv, timeout_s=0.5, max_reply_bytes=4096) as d:
        with pytest.raises(error, match=words) as info:
            d.acquisition_state()
    assert info.value.command == ":ACQuire:STATe?" and info.value.instrument == d.instrument


@pytest.mark.parametrize(
    ("reply", "words"),
    [
        (b"INT16,LSBF,5;1\n", "3 fields"),
        (b"INT64,LSBF,5,1e-8,0,1,0;1\n", "unsupported sample format"),
        (b"INT16,LSBF,five,1e-8,0,1,0;1\n", "non-numeric"),
        (b"INT16,LSBF,5,0,0,1,0;1\n", "out of range"),
        (b"INT16,LSBF,0,1e-8,0,1,0;1\n", "no acquired record on CH1"),
    ],
)
def test_bad_preamble_names_command_and_reply(scripted: Callable[..., ScriptedServer], reply: bytes,
                                              words: str) -> None:
    srv = scripted({PRE: reply, ":CHANnel1:DISPlay?": b"1\n"})  # the channel is on
    with connected(srv) as d, pytest.raises(InstrumentError, match=words) as info:
        d.fetch_waveform(1)
    assert info.value.command == PRE and info.value.reply == reply.decode().strip()


def test_unexpected_state_and_non_ascii_replies(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({":ACQuire:STATe?": b"RUNNING\n", "*IDN?": b"\xff\xfeACME\n"})
    d = Digitizer(srv.resource, timeout_s=1.0)
    with pytest.raises(InstrumentError, match="not ASCII text") as info:
        d.connect()
    assert "\\xff\\xfe" in info.value.reply
    srv2 = scripted({":ACQuire:STATe?": b"RUNNING\n"})
    with connected(srv2) as d2, pytest.raises(InstrumentError, match="unknown acquisition state") as info:
        d2.acquisition_state()
    assert info.value.reply == "RUNNING"


def test_link_dropped_mid_block(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({PRE: b"INT16,LSBF,500,1e-08,0,0.001,0.0;1\n", ":WAVeform:DATA?": b"<drop>"})
    with connected(srv, timeout_s=0.3) as d:
        with pytest.raises(InstrumentError, match="DATA"):
            d.fetch_waveform(1)
        assert not d.connected


def test_a_lab_dialect_is_one_class_named_by_module_and_class(scripted: Callable[..., ScriptedServer]) -> None:
    srv = scripted({":DIGitize:STATus?": b"DONE\n"})
    with Digitizer(srv.resource, timeout_s=1.0, dialect="tests.drivers.vendor_b:VendorBDialect") as d:
        d.arm_single()
        assert d.wait_for_trigger(timeout_s=0.5)
    assert "*CLS;:DIGitize:SINGle;:SYSTem:ERRor?" in srv.received
    with pytest.raises(ValueError, match="not a DigitizerDialect"):
        Digitizer(srv.resource, dialect="tests.drivers.vendor_b:NotADialect")
    with pytest.raises(ValueError, match="unknown dialect 'agilent'"):
        Digitizer(srv.resource, dialect="agilent")


def test_timeout_must_be_positive() -> None:
    with pytest.raises(ValueError, match="timeout_s"):
        Digitizer("TCPIP0::127.0.0.1::1::SOCKET", timeout_s=0)


def test_transfer_benchmark_smoke() -> None:
    """The benchmark runs end to end on a small record in every dialect; it checks itself that
    the three readers return the same samples, and ends with one JSON line."""
    script = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_transfer.py"
    out = subprocess.run(
        [sys.executable, str(script), "--samples", "100000", "--repeats", "1", "--default-repeats", "1"],
        capture_output=True, text=True, timeout=120, check=True,
    ).stdout
    result = json.loads(out.strip().splitlines()[-1])
    assert set(result["dialects"]) == {"generic", "keysight", "tektronix", "lecroy"}
    for row in result["dialects"].values():
        assert row["bytes"] == 200_000 and row["newline_bytes"] > 100
        for key in ("raw_socket_mb_s", "driver_mb_s", "pyvisa_default_mb_s"):
            assert row[key] > 0


def test_closing_one_digitizer_leaves_another_session_of_the_process_open(world: World, faults: FaultSet,
                                                                          server: SimDigitizerServer) -> None:
    # pyvisa keeps one resource manager per VISA library and process: closing it would close
    # every other session (the panel's and a command's, a second digitizer).
    second = SimDigitizerServer(world, FaultSet())
    second.start()
    try:
        with Digitizer(server.resource, timeout_s=2.0, name="first") as first, \
                Digitizer(second.resource, timeout_s=2.0, name="second") as other:
            assert first.identity() and other.identity()
            first.close()
            assert other.identity()  # still answers
    finally:
        second.stop()
