"""The simulated valve/vacuum controller: a pymodbus 3.16 server, TCP or RTU on a pty, in front
of the World.

The datastore is a pymodbus `SimDevice` with four separate blocks (coils, discrete inputs,
holding registers, input registers; bit-addressed coils) holding exactly the mapped points of
the controller map (drivers/sim/controller_map.py, this simulator's own reading of the
register protocol). Like a real controller it answers

- only its unit id: on TCP another id gets exception 0x0B (gateway target did not respond); on
  RTU the request is not for this device and gets no reply at all (RS-485 multi-drop);
- only mapped addresses: a read or write touching an unmapped bit or register (a gap in the
  map, or beyond it) gets exception 0x02 (illegal data address); a write covering only part of
  a 32-bit value likewise.

Its `action` hook (pymodbus 3.13+; overriding a datablock's `setValues` is silently ignored
since then) runs before each request is served: reads refresh the addressed points from the
world (pressures packed per the map, interlocks, valve positions, the coils as commanded, the
watchdog state, the pulse counter); writes go to the world (valves, set-point, projectile,
heartbeat, watchdog time, fire pulse) and a refusal by the controller (interlock chain,
tripped watchdog) is exception 0x04 (device failure).

It fires in one of the fire styles of controller_map.FIRE_STYLES (`fire_style`): a pulse
length written to fire_pulse_ms fires at once (pulse_register), or it is a preset that a
rising edge of the fire coil (coils.fire_command, else coils.fire_valve) or a command word
(holding_registers.fire_command = `fire_command_value`) fires; plc_preset_coil starts with
its own preset (`fire_preset_ms`); host_timed_coil has only the fire valve's coil. A style
that has no use for a signal leaves it a plain memory cell (written, read back, no effect),
as a PLC whose program ignores it would.

RTU runs on a `PtyLine` (drivers/sim/serial_line.py) at the configured baud rate: the host
opens `address` (a pty path) with pyserial as it would a USB-RS485 adapter.

Faults: `modbus-disconnect` closes every TCP connection on the next request (RTU: the
controller stops answering); `modbus-slow` answers each request after `slow_delay_s`.

The server runs its own asyncio loop in one thread; `start()` returns once it listens (TCP
port 0 picks a free port), `stop()` shuts it down and joins the thread.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.pdu.device import ModbusDeviceIdentification
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from hopkinson.drivers.sim.controller_map import (
    BIT_TABLES,
    FIRE_STYLES,
    ControllerMap,
    Point,
    default_map,
)
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.serial_line import PtyLine, byte_time_s
from hopkinson.drivers.sim.world import World

IDENTITY = ("Hopkinson-Sim", "SIMVAC-1", "1.0")  # vendor, product code, revision

# function code -> (table, is a write)
_FUNCTIONS = {1: ("coils", False), 5: ("coils", True), 15: ("coils", True), 2: ("discrete_inputs", False),
              3: ("holding_registers", False), 6: ("holding_registers", True), 16: ("holding_registers", True),
              4: ("input_registers", False)}

_MEI = 0x2B  # encapsulated interface (device identification)
_NOWHERE = 0xFFF0  # a request pointed here is beyond every block: pymodbus answers 0x02
WATCHDOG_CODES = {"off": 0, "armed": 1, "tripped": 2}


class _OneUnit:
    """The server's datastore, answering only `unit_id` (others: NoSuchIdException)."""

    def __init__(self, store: Any, unit_id: int) -> None:
        self._store = store
        self._unit_id = unit_id

    def device_ids(self) -> list[int]:
        return [self._unit_id]

    async def async_getValues(self, device_id: int, *args: Any) -> Any:
        self._check(device_id)
        return await self._store.async_getValues(device_id, *args)

    async def async_setValues(self, device_id: int, *args: Any) -> Any:
        self._check(device_id)
        return await self._store.async_setValues(device_id, *args)

    def _check(self, device_id: int) -> None:
        if device_id != self._unit_id:
            raise NoSuchIdException(f"unit {device_id}")


class SimModbusServer:
    """Modbus face (TCP or RTU) of the world's gas and vacuum controller."""

    def __init__(
        self,
        world: World,
        faults: FaultSet,
        controller_map: ControllerMap | None = None,
        *,
        transport: str = "tcp",
        unit_id: int = 1,
        host: str = "127.0.0.1",
        port: int = 0,
        baudrate: int = 19200,
        parity: str = "N",
        stopbits: int = 1,
        serial_link: str = "",
        slow_delay_s: float = 2.0,
        fire_style: str = "pulse_register",
        fire_preset_ms: float = 150.0,
        fire_command_value: int = 1,
    ) -> None:
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"transport must be 'tcp' or 'rtu', got {transport!r}")
        if fire_style not in FIRE_STYLES:
            raise ValueError(f"fire style must be one of {', '.join(FIRE_STYLES)}, got {fire_style!r}")
        if not 0 < fire_preset_ms <= 60_000:
            raise ValueError(f"fire preset must be in (0, 60000] ms, got {fire_preset_ms!r}")
        self.fire_style = fire_style
        self.fire_command_value = int(fire_command_value)
        self.world = world
        self.faults = faults
        self.map = controller_map or default_map()
        self.transport = transport
        self.unit_id = unit_id
        self.host = host
        self.port = port
        self.baudrate, self.parity, self.stopbits = baudrate, parity, stopbits
        self.slow_delay_s = slow_delay_s
        self.line = PtyLine(byte_time_s(baudrate, 8, parity, stopbits), link_path=serial_link or None,
                            name="sim-modbus-line") if transport == "rtu" else None
        self.last_written: dict[str, float] = {}
        if fire_style != "pulse_register":
            self.last_written["fire_pulse_ms"] = float(fire_preset_ms)  # the PLC's preset at power-on
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self._started = threading.Event()
        self._start_error: BaseException | None = None

    @property
    def address(self) -> str:
        """TCP: "host:port"; RTU: the pty path the host opens (valid after start())."""
        return self.line.port if self.line is not None else f"{self.host}:{self.port}"

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> None:
        """Listen in a background thread; returns once the server is up."""
        if self._thread is not None:
            raise RuntimeError("simulated Modbus server already started")
        if self.line is not None:
            self.line.start()
        self._started.clear()
        self._thread = threading.Thread(target=self._run, name="sim-modbus", daemon=True)
        self._thread.start()
        self._started.wait(10.0)
        if self._start_error is not None or not self._started.is_set():
            self._thread.join(5.0)
            self._thread = None
            if self.line is not None:
                self.line.stop()
            raise RuntimeError(f"simulated Modbus server could not start on {self.address}: {self._start_error}")

    def stop(self) -> None:
        """Close every connection, stop serving and join the thread (idempotent)."""
        if self._thread is None:
            return
        if self._loop is not None and self._stop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10.0)
        self._thread = None
        if self.line is not None:
            self.line.stop()

    def __enter__(self) -> SimModbusServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._serve())
        except BaseException as exc:  # reported by start()
            self._start_error = exc
            self._started.set()
        finally:
            pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
            for task in pending:
                task.cancel()
            if pending:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()

    async def _serve(self) -> None:
        self._stop = asyncio.Event()
        identity = ModbusDeviceIdentification(info_name={
            "VendorName": IDENTITY[0], "ProductCode": IDENTITY[1], "MajorMinorRevision": IDENTITY[2]})
        hooks: dict[str, Any] = {"identity": identity, "trace_pdu": self._pdu, "trace_packet": self._packet}
        if self.line is not None:
            self._server = ModbusSerialServer(
                self._device(), framer=FramerType.RTU, port=self.line.device_port, baudrate=self.baudrate,
                parity=self.parity, stopbits=self.stopbits, ignore_missing_devices=True, **hooks)
        else:
            self._server = ModbusTcpServer(self._device(), address=(self.host, self.port), **hooks)
        self._server.context = _OneUnit(self._server.context, self.unit_id)  # type: ignore[assignment]
        await self._server.serve_forever(background=True)
        sockets = getattr(self._server.transport, "sockets", None) or []
        if sockets:
            self.port = sockets[0].getsockname()[1]
        self._started.set()
        await self._stop.wait()
        self._close_clients()
        await self._server.shutdown()

    def _close_clients(self) -> None:
        if self._server is None:
            return
        for connection in list(self._server.active_connections.values()):
            connection.close()

    def _pdu(self, sending: bool, pdu: Any) -> Any:
        """Each request before it is served: another unit's is dropped (RTU: all; TCP: device
        identification; TCP data requests get 0x0B through _OneUnit); one that touches an
        unmapped address is pointed beyond the datastore, so pymodbus answers 0x02."""
        if sending:
            return pdu
        if pdu.dev_id != self.unit_id and (self.line is not None or pdu.function_code == _MEI):
            return None
        table, _ = _FUNCTIONS.get(pdu.function_code, ("", False))
        if table:
            size = {5: 1, 15: len(pdu.bits), 6: 1, 16: len(pdu.registers)}.get(pdu.function_code, pdu.count)
            if self._points_in(table, range(pdu.address, pdu.address + size)) is None:
                pdu.address = _NOWHERE
        return pdu

    def _packet(self, sending: bool, data: bytes) -> bytes:
        if sending and self.line is not None and self.faults.active("modbus-disconnect"):
            return b""  # an RTU controller that went dead: nothing on the line
        return data

    # -- datastore ------------------------------------------------------------------------
    def _device(self) -> SimDevice:
        blocks = []
        for table in ("coils", "discrete_inputs", "holding_registers", "input_registers"):
            points = self.map.get(table, {}).values()
            if table in BIT_TABLES:
                blocks.append([SimData(p.address, values=False, datatype=DataType.BITS) for p in points])
            else:
                blocks.append([SimData(p.address, count=p.words, values=0, datatype=DataType.REGISTERS)
                               for p in points])
        return SimDevice(id=self.unit_id, simdata=tuple(blocks), action=self._action)  # type: ignore[arg-type]

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """pymodbus calls this before serving each request (see the module docstring)."""
        if self.faults.active("modbus-disconnect"):
            if self.line is None:
                self._close_clients()
            return ExcCodes.DEVICE_FAILURE  # never sent: the TCP connection is gone, RTU stays silent
        if self.faults.active("modbus-slow"):
            await asyncio.sleep(self.slow_delay_s)
        table, _ = _FUNCTIONS.get(function_code, ("", False))
        if not table:
            return ExcCodes.ILLEGAL_FUNCTION
        if set_values is not None:  # a write (pymodbus then reads the written values back)
            span = range(address, address + len(set_values))
            for name, point in (self._points_in(table, span) or {}).items():
                words = [int(set_values[a - address]) for a in point.addresses]
                result = self._write(table, name, bool(words[0]) if table in BIT_TABLES else point.unpack(words))
                if result is not None:
                    return result
            return None
        if table in BIT_TABLES:  # pymodbus passes the count of 16-bit words here: refresh every bit
            for name, point in self.map.get(table, {}).items():
                if 0 <= point.address // 16 - start_address < len(registers):
                    _store_bit(registers, start_address, point.address, bool(self._read(table, name)))
            return None
        for name, point in (self._points_in(table, range(address, address + count)) or {}).items():
            for a, word in zip(point.addresses, point.pack(self._read(table, name)), strict=True):
                registers[a - start_address] = word
        return None

    def _points_in(self, table: str, span: range) -> dict[str, Point] | None:
        """The points a request touches, or None when it touches an unmapped address or only
        part of a multi-word value."""
        touched = {name: p for name, p in self.map.get(table, {}).items()
                   if p.address < span.stop and p.address + p.words > span.start}
        covered = {a for p in touched.values() for a in p.addresses}
        if not set(span) <= covered or not all(set(p.addresses) <= set(span) for p in touched.values()):
            return None
        return touched

    # -- the controller's signals -----------------------------------------------------------
    def _read(self, table: str, name: str) -> float:
        w = self.world
        if table == "coils":
            if name == "fire_command" or (name == "fire_valve" and self._fire_coil() == "fire_valve"):
                return self.last_written.get(name, 0.0)  # a memory bit of the PLC's program
            return w.coils()[_COIL_KEYS[name]]
        if table == "discrete_inputs":
            if name.endswith("_open"):
                return w.valve_positions()[name.split("_")[0]]
            return {"door_closed": w.door_closed, "fixture_clamped": w.fixture_clamped,
                    "estop_healthy": w.estop_healthy}[name]()
        if table == "holding_registers":
            if name == "pressure_setpoint":
                return w.pressure_setpoint_bar()
            if name == "projectile":
                return w.projectile()
            if name == "watchdog_ms":
                return w.watchdog_s() * 1000.0
            return self.last_written.get(name, 0.0)
        return {"reservoir_pressure": w.reservoir_pressure_bar, "fixture_vacuum": w.fixture_vacuum_mbar,
                "watchdog_state": lambda: WATCHDOG_CODES[w.watchdog_state()],
                "fire_pulse_count": lambda: w.fire_pulses}[name]()

    def _write(self, table: str, name: str, value: float) -> ExcCodes | None:
        w = self.world
        previous = self.last_written.get(name, 0.0)
        self.last_written[name] = float(value)
        if table == "coils":
            if name == self._fire_coil():
                refused = self._fire_edge(bool(value) and not previous)
                if refused is not None:
                    self.last_written[name] = previous  # refused: the bit stays as it was
                return refused
            if name == "fire_command":
                return None  # a memory bit this PLC's program does not use
            setter = {"fire_valve": w.set_fire_valve, "fill_valve": w.set_fill_valve,
                      "vent_valve": w.set_vent_valve, "vacuum_pump": w.set_pump}[name]
            refusal = setter(bool(value))
            # A fire command the interlock chain refuses leaves the coil shut (reads back shut),
            # as today's hosts check; energising anything while tripped is refused outright.
            return ExcCodes.DEVICE_FAILURE if refusal and "watchdog" in refusal else None
        if name == "pressure_setpoint":
            w.set_pressure_setpoint_bar(value)
        elif name == "projectile":
            if value not in (1, 2, 3):
                return ExcCodes.ILLEGAL_VALUE
            w.load_projectile(int(value))
        elif name == "heartbeat":
            w.heartbeat(int(value))
        elif name == "watchdog_ms":
            if not 0 < value <= 3_600_000:
                return ExcCodes.ILLEGAL_VALUE
            w.set_watchdog_s(value / 1000.0)
        elif name == "fire_pulse_ms":
            if not 0 < value <= 60_000:
                self.last_written[name] = previous
                return ExcCodes.ILLEGAL_VALUE
            if self.fire_style == "pulse_register" and w.fire_pulse(value / 1000.0):
                return ExcCodes.DEVICE_FAILURE
        elif name == "fire_command" and self.fire_style == "preset_and_command":
            refused = ExcCodes.ILLEGAL_VALUE if value not in (0, self.fire_command_value) else \
                self._fire_edge(value == self.fire_command_value and previous != value)
            if refused is not None:
                self.last_written[name] = previous
            return refused
        return None

    def _fire_coil(self) -> str:
        """The coil whose rising edge fires the preset ("" in the styles without one)."""
        if self.fire_style not in ("preset_and_coil", "plc_preset_coil"):
            return ""
        return "fire_command" if "fire_command" in self.map.get("coils", {}) else "fire_valve"

    def _fire_edge(self, rising: bool) -> ExcCodes | None:
        """A fire coil or command word switched on: a pulse of the preset (refused: 0x04)."""
        preset_ms = self.last_written.get("fire_pulse_ms", 0.0)
        if not rising or preset_ms <= 0:
            return None  # no preset: the PLC's timer has nothing to run
        if self.world.fire_pulse(preset_ms / 1000.0):
            return ExcCodes.DEVICE_FAILURE
        return None


_COIL_KEYS = {"fire_valve": "fire", "fill_valve": "fill", "vent_valve": "vent", "vacuum_pump": "pump"}


def _store_bit(registers: list[int], start_register: int, bit_address: int, value: bool) -> None:
    """Set one bit in pymodbus's packed bit block (16 bits per register, bit 0 first)."""
    index = bit_address // 16 - start_register
    mask = 1 << (bit_address % 16)
    registers[index] = (registers[index] | mask) if value else (registers[index] & ~mask)
