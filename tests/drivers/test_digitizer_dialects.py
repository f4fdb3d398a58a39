"""Every digitizer dialect against its own simulator over loopback through pyvisa (pyvisa-py):
settings written and read back (and checked in the simulated instrument itself), every sample
format in both byte orders against codes computed here, the trigger honoured, and the IEEE
488.2 status commands and *OPC? as the standard says. A plain pyvisa client reads each
simulator without the project's driver."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import numpy as np
import pytest
import pyvisa

from hopkinson.drivers.digitizer import Digitizer
from hopkinson.drivers.digitizer_settings import DigitizerSettings
from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.scpi_digitizer import SimDigitizerServer
from tests.drivers.digitizer_world import CHANNELS, FORMATS, STEP_V, World, expected_codes, rails

N = 4_000
DIALECTS = tuple(CHANNELS)


def configured(dialect: str, **changes: object) -> DigitizerSettings:
    ch1, ch2 = CHANNELS[dialect][:2]
    base = DigitizerSettings(sample_rate_hz=125e6, record_length=N, pre_trigger_samples=N // 10,
                             ranges_v={ch1: 1.0, ch2: 10.0}, trigger_source=ch2, trigger_level_v=0.5,
                             trigger_slope="POS")
    return base.with_changes(**changes)


@pytest.fixture
def world() -> World:
    return World()


def serve(dialect: str, world: World) -> SimDigitizerServer:
    server = SimDigitizerServer(world, FaultSet(), dialect=dialect)
    server.start()
    return server


@pytest.fixture(params=DIALECTS)
def scope(request: pytest.FixtureRequest, world: World) -> Iterator[tuple[str, SimDigitizerServer]]:
    server = serve(request.param, world)
    yield request.param, server
    server.stop()


def driver(dialect: str, server: SimDigitizerServer, **kw: object) -> Digitizer:
    roles = {"doppler": CHANNELS[dialect][0], "response": CHANNELS[dialect][1]}
    return Digitizer(server.resource, timeout_s=2.0, name=f"{dialect} scope", dialect=dialect, channels=roles,
                     **kw)  # type: ignore[arg-type]


def test_settings_are_written_and_read_back_in_each_dialect(scope: tuple[str, SimDigitizerServer]) -> None:
    dialect, server = scope
    wanted = configured(dialect)
    with driver(dialect, server) as dig:
        dig.configure(wanted)
        held = dig.settings()
    assert held.differences(wanted) == [] and wanted.differences(held) == []
    # the instrument's own state: 10 % pre-trigger is 400 samples, a ±10 V channel reads ±10 V
    state = server.settings
    assert (state.sample_rate_hz, state.record_length, state.pre_trigger_samples) == (125e6, N, N // 10)
    assert (state.ch_range_v[1], state.ch_range_v[2]) == pytest.approx((1.0, 10.0))
    assert (state.trigger_source, state.trigger_level_v, state.trigger_slope) == ("CH2", 0.5, "POS")
    assert held.ranges_v[CHANNELS[dialect][1]] == pytest.approx(10.0)
    assert held.pre_trigger_samples == N // 10


def test_a_changed_setting_is_seen_in_the_read_back(scope: tuple[str, SimDigitizerServer]) -> None:
    dialect, server = scope
    wanted = configured(dialect)
    with driver(dialect, server) as dig, driver(dialect, server) as other:
        dig.configure(wanted)
        other.configure(wanted.with_changes(sample_rate_hz=50e6, trigger_slope="NEG"))  # a second client
        differences = wanted.differences(dig.settings())
    assert len(differences) == 2
    assert differences[0].startswith("sample_rate_hz: 1.25e+08 configured, 5e+07 on the instrument")
    assert differences[1].startswith("trigger_slope: POS configured, NEG")


@pytest.mark.parametrize(("dialect", "sample_format", "byte_order"), [
    (d, f, o) for d in DIALECTS for f in FORMATS[d] for o in ("little", "big")])
def test_every_sample_format_in_both_byte_orders(world: World, dialect: str, sample_format: str,
                                                byte_order: str) -> None:
    server = serve(dialect, world)
    try:
        with driver(dialect, server, sample_format=sample_format, byte_order=byte_order) as dig:
            dig.configure(configured(dialect))
            dig.arm_single()
            world.fire()
            assert dig.wait_for_trigger(2.0)
            doppler, response = dig.fetch_waveform("doppler"), dig.fetch_waveform("response")
    finally:
        server.stop()
    truth = world.record(world.seen[-1])
    for wave, volts, range_v in ((doppler, truth[1], 1.0), (response, truth[2], 10.0)):
        codes = expected_codes(volts, range_v, sample_format, dialect)
        assert wave.codes.dtype == np.dtype(sample_format)  # native dtype, native byte order
        np.testing.assert_array_equal(wave.codes, codes)
        assert wave.trigger_index == N // 10
        lsb = 2 * range_v / (255 if sample_format.endswith("8") else 65535) if sample_format != "float32" else 0.0
        inside = np.abs(volts) < range_v
        assert np.max(np.abs(wave.volts()[inside] - volts[inside])) <= 0.51 * lsb + 1e-6 * range_v
        beyond = int(np.count_nonzero(np.abs(volts) >= range_v))  # every sample past the range counts
        if sample_format == "float32":
            assert wave.clipped_samples() == beyond
        else:  # ... and those that round onto a rail (within half a code of full scale)
            low, high = rails(sample_format, dialect)
            assert wave.code_range == (low, high)
            assert wave.clipped_samples() == np.count_nonzero((codes == low) | (codes == high)) >= beyond
            if wave is doppler:  # the sine clips low as well as high
                assert np.count_nonzero(codes == low) > 0 and np.count_nonzero(codes == high) > 0
    assert doppler.clipped_samples() > 0 and response.clipped_samples() == 0
    if sample_format == "uint16":
        assert response.codes.max() > 40_000  # never wrapped to a negative number
    step = response.volts()[N // 10]
    assert response.volts()[N // 10 - 1] < 0.5 <= step  # the record sits on its trigger's crossing
    assert response.volts()[-1] == pytest.approx(STEP_V, abs=0.1)


@pytest.mark.parametrize("wrong", ["source", "level", "slope"])
def test_a_wrong_trigger_captures_nothing(scope: tuple[str, SimDigitizerServer], world: World, wrong: str) -> None:
    dialect, server = scope
    changes = {"source": {"trigger_source": CHANNELS[dialect][2]},  # nothing connected there
               "level": {"trigger_level_v": STEP_V + 1.0},           # above the signal
               "slope": {"trigger_slope": "NEG"}}[wrong]              # the step only rises
    with driver(dialect, server) as dig:
        dig.configure(configured(dialect, **changes))
        dig.arm_single()
        world.fire()
        assert dig.wait_for_trigger(0.2) is False
        assert dig.acquisition_state() == "ARMED"
        assert world.captures == 0 and not world.fired.is_set()  # the shot went by unrecorded


def test_fetch_without_a_record_is_a_clear_error(scope: tuple[str, SimDigitizerServer]) -> None:
    dialect, server = scope
    with driver(dialect, server) as dig:
        dig.configure(configured(dialect))
        with pytest.raises(InstrumentError, match=f"no acquired record on {CHANNELS[dialect][0]}") as info:
            dig.fetch_waveform("doppler")
        assert f"{dialect} scope" in str(info.value)
        assert dig.identity()  # still in step


def test_a_refused_setting_names_the_instrument_and_the_command(scope: tuple[str, SimDigitizerServer]) -> None:
    dialect, server = scope
    with driver(dialect, server) as dig:
        with pytest.raises(InstrumentError, match="refused by the instrument") as info:
            dig.configure(configured(dialect, sample_rate_hz=1e12))  # beyond the instrument
        assert info.value.instrument == dig.instrument and server.resource in info.value.instrument
        assert info.value.reply
        dig.configure(configured(dialect))  # the error state does not leak into the next command
        assert dig.settings().sample_rate_hz == 125e6


def test_the_armed_instrument_refuses_changes(scope: tuple[str, SimDigitizerServer]) -> None:
    dialect, server = scope
    with driver(dialect, server) as dig:
        dig.configure(configured(dialect))
        dig.arm_single()
        with pytest.raises(InstrumentError, match="refused"):
            dig.configure(configured(dialect, record_length=2 * N))
        dig.abort()
        assert dig.acquisition_state() == "IDLE"


# -- a plain pyvisa client, without the project's driver ---------------------------------------

PLAIN = {  # set-up, arm, the data query, pyvisa datatype / byte order of the block
    "generic": ([":ACQ:POIN 4000", ":ACQ:PRET 400", ":TRIG:SOUR CH2", ":TRIG:LEV 0.5", ":WAV:FORM INT16",
                 ":WAV:BYT LSBF", ":WAV:SOUR CH2"], ":SING", ":WAV:DATA?", "h", False),
    "keysight": ([":CHAN2:DISP ON", ":ACQ:POIN 4000", ":TIM:REF LEFT", ":TIM:POS -4E-6", ":TRIG:EDGE:SOUR CHAN2",
                  ":TRIG:EDGE:LEV 0.5", ":WAV:FORM WORD", ":WAV:UNS 0", ":WAV:BYT MSBF", ":WAV:SOUR CHAN2",
                  ":WAV:POIN:MODE RAW", ":WAV:POIN MAX"],  # *RST sends the screen's 1000 points
                 ":SING", ":WAV:DATA?", "h", True),
    "tektronix": (["SEL:CH2 ON", "HOR:MODE:RECO 4000", "HOR:POS 10", "TRIG:A:EDGE:SOU CH2", "TRIG:A:LEV:CH2 0.5",
                   "DATA:ENC SRI", "DATA:WID 2", "DATA:START 1", "DATA:STOP 4000", "DATA:SOU CH2"],
                  "ACQ:STOPA SEQ;:ACQ:STATE RUN", "CURV?", "h", False),
    "lecroy": (["CHDR OFF", "C2:TRA ON", "MSIZ 4000", "TDIV 4E-6", "TRDL 10", "TRSE EDGE,SR,C2", "C2:TRLV 0.5", "C2:TRSL POS",
                "CFMT DEF9,WORD,BIN", "CORD LO"], "TRMD SINGLE", "C2:WF? DAT1", "h", False),
}


def plain_record(server: SimDigitizerServer, world: World, dialect: str, setup: list[str]) -> tuple[np.ndarray, str]:
    """A plain pyvisa client sets up, arms, fires and reads channel 2: (its codes, *ESR? after)."""
    _, arm, data_query, datatype, big_endian = PLAIN[dialect]
    rm = pyvisa.ResourceManager("@py")
    inst = rm.open_resource(server.resource, read_termination="\n", write_termination="\n", timeout=2000)
    try:
        assert inst.query("*IDN?").count(",") == 3
        for command in setup:
            inst.write(command)
        inst.write(arm)
        world.fire()
        assert inst.query("*OPC?") == "1"
        codes = inst.query_binary_values(data_query, datatype=datatype, is_big_endian=big_endian,
                                         container=np.array)
        return codes, inst.query("*ESR?")
    finally:
        inst.close()
        rm.close()


def test_a_plain_pyvisa_client_reads_each_simulator(scope: tuple[str, SimDigitizerServer], world: World) -> None:
    dialect, server = scope
    codes, esr = plain_record(server, world, dialect, PLAIN[dialect][0])
    assert esr == "0"  # no command was refused
    state = world.seen[-1]
    assert state.record_length == 4000 and state.pre_trigger_samples == 400 and state.trigger_level_v == 0.5
    np.testing.assert_array_equal(codes, expected_codes(world.record(state)[2], state.ch_range_v[2], "int16",
                                                        dialect))


# -- channels on or off (issue 21): a scope acquires only the channels that are on ---------------

ON_QUERY = {"generic": ":CHAN{n}:DISP?", "keysight": ":CHAN{n}:DISP?", "tektronix": "SEL:CH{n}?",
            "lecroy": "C{n}:TRA?"}
POWER_ON = {"generic": (True, True), "keysight": (True, False), "tektronix": (True, False),
            "lecroy": (True, False)}  # channels 1 and 2 after power-on and *RST, as the real instruments


def _plain(server: SimDigitizerServer) -> pyvisa.resources.MessageBasedResource:
    return pyvisa.ResourceManager("@py").open_resource(server.resource, read_termination="\n",
                                                       write_termination="\n", timeout=2000)


def _turn_off_channel_2(inst: pyvisa.resources.MessageBasedResource, dialect: str) -> None:
    """Another program turns channel 2 off (and its query confirms it was done)."""
    query = ON_QUERY[dialect].format(n=2)
    inst.write(query.replace("?", " OFF"))
    assert not _on(inst.query(query))


def _on(reply: str) -> bool:
    return reply.split()[-1].upper() in ("1", "ON")  # Tektronix and LeCroy may put a header first


def test_each_simulator_powers_on_and_resets_with_its_instruments_channels(scope) -> None:
    dialect, server = scope
    inst = _plain(server)
    try:
        queries = [ON_QUERY[dialect].format(n=n) for n in (1, 2)]
        assert tuple(_on(inst.query(q)) for q in queries) == POWER_ON[dialect]
        inst.write(queries[1].replace("?", " ON"))
        assert _on(inst.query(queries[1]))
        inst.write("*RST")
        assert tuple(_on(inst.query(q)) for q in queries) == POWER_ON[dialect]
    finally:
        inst.close()


@pytest.mark.parametrize("dialect", ("keysight", "tektronix", "lecroy"))
def test_a_channel_left_off_after_power_on_is_not_acquired(dialect: str, world: World) -> None:
    # The scope: channel 2 never turned on, the acquisition runs, its transfer is empty.
    server = serve(dialect, world)
    try:
        setup = [c for c in PLAIN[dialect][0] if c not in ("SEL:CH2 ON", ":CHAN2:DISP ON", "C2:TRA ON")]
        codes, _ = plain_record(server, world, dialect, setup)
    finally:
        server.stop()
    assert codes.size == 0


def test_the_driver_turns_on_every_recorded_channel_and_reads_them_back(scope) -> None:
    dialect, server = scope
    wanted = configured(dialect)
    ch1, ch2 = CHANNELS[dialect][:2]
    with driver(dialect, server) as dig:
        dig.configure(wanted)  # from the power-on state: only channel 1 on for a scope
        assert server.channels_on[1] and server.channels_on[2]
        held = dig.settings()
        assert held.channels_on == {ch1: True, ch2: True} and wanted.differences(held) == []
        other = _plain(server)
        try:
            _turn_off_channel_2(other, dialect)
        finally:
            other.close()
        assert wanted.differences(dig.settings()) == [
            f"{ch2}: off on the instrument (the rig records it: it must be on, or nothing is acquired on it)"]


def test_a_transfer_of_a_channel_turned_off_names_the_channel(scope, world: World) -> None:
    dialect, server = scope
    ch2 = CHANNELS[dialect][1]
    with driver(dialect, server) as dig:
        dig.configure(configured(dialect))
        dig.arm_single()
        other = _plain(server)
        try:
            _turn_off_channel_2(other, dialect)
        finally:
            other.close()
        world.fire()
        assert dig.wait_for_trigger(2.0)
        assert dig.fetch_waveform("doppler").codes.size == N  # channel 1 was on: recorded
        with pytest.raises(InstrumentError, match=f"{ch2} is off on the instrument") as info:
            dig.fetch_waveform("response")
        assert f"turn {ch2} on" in str(info.value) and info.value.instrument == dig.instrument


def test_a_decimated_keysight_transfer_is_refused(world: World) -> None:
    # A Keysight scope sends :WAVeform:POINts points (1000 after *RST), every k-th sample of a
    # longer record: the driver asks for them all, and a transfer of fewer is not the shot.
    server = serve("keysight", world)
    try:
        with driver("keysight", server) as dig:
            dig.configure(configured("keysight"))
            dig.arm_single()
            world.fire()
            assert dig.wait_for_trigger(2.0)
            assert dig.fetch_waveform("response").codes.size == N  # MAXimum: the whole record
            with pyvisa.ResourceManager("@py").open_resource(server.resource, read_termination="\n",
                                                             write_termination="\n") as other:
                other.write(":WAVeform:POINts 1000")  # another client, or a dialect that forgot
                assert other.query(":WAVeform:POINts?") == "+1000"
            with pytest.raises(InstrumentError, match="sends 1000 points of the 4000 configured") as info:
                dig.fetch_waveform("response")
            assert info.value.command.endswith(":WAVeform:PREamble?;:WAVeform:UNSigned?;:WAVeform:BYTeorder?")
    finally:
        server.stop()


# -- IEEE 488.2 --------------------------------------------------------------------------------


class Raw:
    """A bare socket client: one message out, one reply line (or none) back."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=2.0)
        self.buffer = b""

    def send(self, message: str) -> None:
        self.sock.sendall(message.encode() + b"\n")

    def line(self, timeout_s: float = 2.0) -> str | None:
        self.sock.settimeout(timeout_s)
        try:
            while b"\n" not in self.buffer:
                data = self.sock.recv(65536)
                if not data:
                    return None
                self.buffer += data
        except TimeoutError:
            return None
        line, self.buffer = self.buffer.split(b"\n", 1)
        return line.decode()

    def ask(self, message: str) -> str | None:
        self.send(message)
        return self.line()

    def close(self) -> None:
        self.sock.close()


ARM = {"generic": ":SINGle", "keysight": ":SINGle", "tektronix": "ACQuire:STATE RUN", "lecroy": "TRMD SINGLE"}
TRIGGER_ON_CH2 = {"generic": ":TRIG:SOUR CH2;:TRIG:LEV 0.5", "keysight": ":TRIG:EDGE:SOUR CHAN2;:TRIG:EDGE:LEV 0.5",
                  "tektronix": "TRIG:A:EDGE:SOU CH2;:TRIG:A:LEV:CH2 0.5", "lecroy": "TRSE EDGE,SR,C2;C2:TRLV 0.5"}
SHORT = {"generic": ":ACQ:POIN 2000;:ACQ:PRET 200", "keysight": ":ACQ:POIN 2000", "tektronix": "HOR:RECO 2000",
         "lecroy": "MSIZ 2000"}


def test_opc_query_waits_for_the_acquisition(scope: tuple[str, SimDigitizerServer], world: World) -> None:
    dialect, server = scope
    client = Raw(server.port)
    try:
        client.send(f"{SHORT[dialect]};{TRIGGER_ON_CH2[dialect]};{ARM[dialect]}")
        client.send("*OPC?")
        assert client.line(timeout_s=0.3) is None  # armed: *OPC? does not answer 1
        world.fire()
        assert client.line() == "1"
        client.send(f"{ARM[dialect]};*WAI;*IDN?")  # *WAI holds the rest of the message
        assert client.line(timeout_s=0.2) is None
        world.fire()
        assert client.line().count(",") >= 3
        client.send(f"*CLS;{ARM[dialect]};*OPC")  # *OPC: ESR bit 0 once the acquisition is done
        assert client.ask("*ESR?") == "0"
        world.fire()
        deadline = time.monotonic() + 2.0
        while (esr := client.ask("*ESR?")) == "0" and time.monotonic() < deadline:
            time.sleep(0.01)
        assert esr == "1"
    finally:
        client.close()


def test_ieee488_status_registers(scope: tuple[str, SimDigitizerServer]) -> None:
    dialect, server = scope
    client = Raw(server.port)
    try:
        assert client.ask("*TST?") == "0"
        client.send("*CLS;*ESE 60;*SRE 32")
        assert client.ask("*ESE?;*SRE?") == "60;32"
        assert client.ask("*STB?") == "0"
        client.send("FOO:BAR 1")  # an undefined header: a command error
        stb = int(client.ask("*STB?"))
        assert stb & 0x20 and stb & 0x40  # event summary (CME enabled by *ESE) and master summary
        assert client.ask("*ESR?") == "32"
        assert client.ask("*ESR?") == "0"  # reading cleared it
        if dialect in ("generic", "keysight"):
            client.send("FOO:BAR 2;FOO:BAZ 3")
            assert client.ask(":SYST:ERR:COUN?") in ("3", "+3")  # the first error was not read yet
            assert client.ask(":SYST:ERR?").endswith('"Undefined header; FOO:BAR 1"')
            client.send("*CLS")
            assert client.ask(":SYST:ERR:COUN?") in ("0", "+0")
    finally:
        client.close()


def test_lecroy_reads_a_block_behind_a_response_header(world: World) -> None:
    """Another client switched the response headers back on (CHDR SHORT): the waveform then
    comes as "C2:WF ALL,#9..." and the dialect reads the descriptor and samples behind it."""
    server = serve("lecroy", world)
    try:
        with driver("lecroy", server) as dig:
            dig.configure(configured("lecroy"))
            dig.arm_single()
            world.fire()
            assert dig.wait_for_trigger(2.0)
            other = Raw(server.port)
            other.send("CHDR SHORT")
            assert other.ask("TDIV?").startswith("TDIV ")
            other.close()
            seen: list[str] = []
            dig.trace = lambda record: seen.append(record.text)
            wave = dig.fetch_waveform("response")
    finally:
        server.stop()
    assert f"C2:WF ALL,<binary block: {346 + 2 * N} bytes>" in seen
    np.testing.assert_array_equal(wave.codes, expected_codes(world.record(world.seen[-1])[2], 10.0, "int16"))
