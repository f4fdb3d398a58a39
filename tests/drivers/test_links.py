"""The links under every driver: bounded reads, exclusive serial ports, the simulated line's byte
time, and the Modbus driver against pymodbus's own server and against a device that floods."""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import threading
import time
from collections.abc import Iterator

import pytest
import serial
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from hopkinson.drivers.amplifier import BridgeAmplifier
from hopkinson.drivers.base import read_bounded, trace_text
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.modbus_link import ModbusDriver, ModbusTarget
from hopkinson.drivers.registers import Register
from hopkinson.drivers.sim.serial_line import PtyLine, byte_time_s
from hopkinson.drivers.sim.simulated_rig import SimulatedRig
from hopkinson.drivers.valve_controller import ValveController
from tests.drivers.conftest import controller_for, sim_config


# -- bounded reads ----------------------------------------------------------------------------------
def test_read_bounded_stops_an_endless_reply_at_its_size_limit() -> None:
    chunks = iter([b"abc"] * 1000)
    with pytest.raises(InstrumentError, match="reply longer than 12 bytes without b'\\\\n'") as caught:
        read_bounded(lambda n, wait_s: next(chunks)[:n], terminator=b"\n", max_bytes=12, timeout_s=5.0,
                     instrument="gauge", command="P?")
    assert (caught.value.instrument, caught.value.command, caught.value.reply) == ("gauge", "P?", "abcabcabcabc")


def test_read_bounded_keeps_one_deadline_over_a_trickle() -> None:
    def trickle(n: int, wait_s: float) -> bytes:
        time.sleep(min(wait_s, 0.02))
        return b"x"

    with pytest.raises(InstrumentTimeout, match="no complete reply within 0.2 s"):
        read_bounded(trickle, terminator=b"\n", max_bytes=10_000, timeout_s=0.2, instrument="gauge", command="P?")
    assert read_bounded(lambda n, w: b"ok\nmore", terminator=b"\n", max_bytes=10, timeout_s=1.0,
                        instrument="g", command="c") == b"ok\n"


def test_traces_keep_text_and_summarise_binary_blocks() -> None:
    assert trace_text(b"*IDN?\n") == "*IDN?" and trace_text("GAIN 20*23\r\n") == "GAIN 20*23"
    assert trace_text(b"#6400000" + bytes(range(256)) * 1563) == "<binary block: 400136 bytes>"
    assert trace_text(b"\x01\x03\x00") == "<binary: 01 03 00>"
    assert trace_text("x" * 500) == "x" * 200 + "... (500 chars)"


@pytest.fixture
def line() -> Iterator[PtyLine]:
    with PtyLine(byte_time_s(921600)) as pty:
        yield pty


def test_a_serial_device_streaming_without_newline_is_an_error_within_the_timeout(line: PtyLine) -> None:
    stop = threading.Event()

    def flood() -> None:  # a broken device: bytes and never an end of line
        while not stop.is_set():
            with contextlib.suppress(OSError):
                os.write(line.device_fd, b"\x00" * 64)
            time.sleep(0.001)

    flooder = threading.Thread(target=flood)
    flooder.start()
    try:
        with BridgeAmplifier(line.port, timeout_s=1.0, retries=1) as amp:
            with pytest.raises(InstrumentError, match="reply longer than 256 bytes") as caught:
                amp.gain()
    finally:
        stop.set()
        flooder.join()
    assert caught.value.command == "GAIN?" and caught.value.instrument == f"bridge amplifier {line.port}"


def test_serial_ports_are_opened_exclusively(line: PtyLine) -> None:
    with BridgeAmplifier(line.port, timeout_s=0.2):
        second = BridgeAmplifier(line.port, timeout_s=0.2, name="status's amplifier")
        with pytest.raises(InstrumentConnectionError, match="held by another process") as caught:
            second.connect()
        assert caught.value.instrument == "status's amplifier"
        with pytest.raises(serial.SerialException):  # any pyserial client honours the lock
            serial.Serial(line.port, exclusive=True)
    BridgeAmplifier(line.port, timeout_s=0.2).connect()  # free again once closed


def test_an_rtu_port_is_exclusive_too() -> None:
    with SimulatedRig(sim_config(modbus_transport="rtu")) as rig, controller_for(rig, timeout_s=1.0) as first:
        assert first.reservoir_pressure_bar() == 0.0
        with pytest.raises(InstrumentConnectionError, match="held by another process"):
            controller_for(rig, timeout_s=1.0).connect()


@pytest.mark.parametrize("baudrate", [115200, 19200])
def test_the_simulated_serial_line_keeps_the_byte_time(baudrate: int) -> None:
    # 20 amplifier round trips: "GAIN?*XX\n" (9 bytes) out, "GAIN 10*XX\n" (11 bytes) back.
    config = sim_config()
    config = type(config)(world=config.world, register_map=config.register_map,
                          servers=type(config.servers)(amplifier_baudrate=baudrate))
    with SimulatedRig(config) as rig, BridgeAmplifier(rig.addresses.serial_port, baudrate=baudrate) as amp:
        start = time.perf_counter()
        for _ in range(20):
            amp.gain()
        elapsed = time.perf_counter() - start
    theory = 20 * 20 * 10 / baudrate  # 8N1: 10 bits per byte
    assert elapsed >= 0.95 * theory  # never faster than the line (a loaded machine is only slower)


# -- Modbus against pymodbus's own server ---------------------------------------------------------
@contextlib.contextmanager
def pymodbus_server(device: SimDevice) -> Iterator[int]:
    """pymodbus's own TCP server on a free port, in its own loop thread."""
    started = threading.Event()
    state: dict[str, object] = {}

    def run() -> None:
        loop = asyncio.new_event_loop()
        state["loop"] = loop

        async def serve() -> None:
            server = ModbusTcpServer(device, address=("127.0.0.1", 0))
            await server.serve_forever(background=True)
            state["port"] = server.transport.sockets[0].getsockname()[1]  # type: ignore[union-attr]
            stop = asyncio.Event()
            state["stop"] = stop
            started.set()
            await stop.wait()
            await server.shutdown()

        loop.run_until_complete(serve())
        loop.close()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert started.wait(10.0)
    try:
        yield int(state["port"])  # type: ignore[arg-type]
    finally:
        loop = state["loop"]
        loop.call_soon_threadsafe(state["stop"].set)  # type: ignore[union-attr, attr-defined]
        thread.join(10.0)


def test_typed_registers_against_pymodbus_s_own_server() -> None:
    # pymodbus packs these values itself (DataType.INT32 / FLOAT32 / UINT32, big word order).
    device = SimDevice(id=3, simdata=[
        SimData(10, values=-123456, datatype=DataType.INT32),
        SimData(20, values=2.75, datatype=DataType.FLOAT32),
        SimData(30, values=4_000_000_000, datatype=DataType.UINT32),
        SimData(40, values=0x8001, datatype=DataType.REGISTERS),
    ])
    with pymodbus_server(device) as port, ModbusDriver(ModbusTarget(host="127.0.0.1", port=port, unit_id=3)) as dev:
        values = dev.read_values("holding registers", {
            "counts": Register(10, "int32", scale=0.5), "gauge": Register(20, "float32", offset=-0.75),
            "total": Register(30, "uint32"), "signed": Register(40, "int16")})
        assert values == {"counts": -61728.0, "gauge": 2.0, "total": 4e9, "signed": -32767.0}
        dev.write_value(Register(20, "float32"), -1.25, "gauge")
        assert dev.read_values("holding registers", {"g": Register(20, "float32")})["g"] == -1.25
        with pytest.raises(InstrumentError, match="Modbus exception 2"):  # 50 is beyond its blocks
            dev.read_words("holding registers", [50])


def test_the_valve_controller_driver_runs_against_pymodbus_s_own_server() -> None:
    # A plain pymodbus device laid out as the reference map (four blocks, no simulator logic).
    bits = [SimData(a, values=v, datatype=DataType.BITS) for a, v in ((0, False), (1, False), (2, False), (3, False))]
    inputs = [SimData(a, values=v, datatype=DataType.BITS)
              for a, v in ((0, True), (1, True), (2, False), (8, False), (9, True), (10, False))]
    device = SimDevice(id=1, simdata=(
        bits, inputs,
        [SimData(0, values=[1234, 1, 0, 3000, 0], datatype=DataType.REGISTERS)],
        [SimData(0, values=[2500, 10132, 2], datatype=DataType.REGISTERS),
         SimData(4, values=7, datatype=DataType.UINT32)],
    ))
    with pymodbus_server(device) as port, ValveController.tcp("127.0.0.1", port, timeout_s=2.0) as vc:
        status = vc.status()
        assert status.reservoir_pressure_bar == 2.5 and status.pressure_setpoint_bar == 1.234
        assert status.fixture_vacuum_mbar == pytest.approx(1013.2)
        assert status.watchdog == "tripped" and status.fire_pulse_count == 7
        assert status.interlocks.problems() == ["e-stop tripped"]
        assert status.valves.mismatches() == ["fill valve commanded shut but open"]
        vc.set_vent_valve(True)
        assert vc.valves().vent_valve is True
        vc.set_pressure_setpoint_bar(4.5)
        assert vc.pressure_setpoint_bar() == 4.5


def test_a_device_that_floods_the_link_is_an_error_not_a_growing_buffer() -> None:
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        stop = threading.Event()

        def flood() -> None:
            conn, _ = listener.accept()
            with conn:
                conn.settimeout(2.0)
                with contextlib.suppress(OSError):
                    conn.recv(256)  # the request
                    while not stop.is_set():
                        conn.sendall(b"\xff" * 4096)  # never a Modbus frame

        server = threading.Thread(target=flood)
        server.start()
        try:
            dev = ModbusDriver(ModbusTarget(host="127.0.0.1", port=listener.getsockname()[1]), timeout_s=2.0)
            with dev, pytest.raises(InstrumentError, match="longer than any Modbus frame") as caught:
                dev.read_words("input registers", [0])
            assert caught.value.command == "read input registers 0"
        finally:
            stop.set()
            server.join(5.0)
