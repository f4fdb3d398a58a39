"""The simulated valve/vacuum controller: a pymodbus 3.16 TCP server in front of the World.

The datastore is a pymodbus `SimDevice` with four separate blocks (coils, discrete inputs,
holding registers, input registers; bit-addressed coils) laid out by the same RegisterMap
the driver uses. Its `action` hook (pymodbus 3.13+; overriding a datablock's `setValues` is
silently ignored since then) runs before every request is served:

- reads refresh the addressed block from the world (pressures scaled to counts, interlocks,
  the coils as the valves really are: a fire command refused by the interlock chain reads
  back shut);
- writes go to the world (valve coils, set-point, projectile) before pymodbus stores them.

Faults: `modbus-disconnect` closes every client connection on the next request (the
request is not answered); `modbus-slow` answers each request after `slow_delay_s`.

The server runs its own asyncio loop in one thread; `start()` returns once it listens (port 0
picks a free port), `stop()` shuts it down and joins the thread.
"""

from __future__ import annotations

import asyncio
import threading

from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.world import World
from hopkinson.drivers.valve_controller import UINT16_MAX, RegisterMap
from pymodbus.constants import ExcCodes
from pymodbus.pdu.device import ModbusDeviceIdentification
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

IDENTITY = ("Hopkinson-Sim", "SIMVAC-1", "1.0")  # vendor, product code, revision

_READ_COILS, _READ_DISCRETE, _READ_HOLDING, _READ_INPUT = 1, 2, 3, 4
_WRITE_COIL, _WRITE_REGISTER, _WRITE_COILS, _WRITE_REGISTERS = 5, 6, 15, 16


class SimModbusServer:
    """Modbus TCP face of the world's gas and vacuum controller."""

    def __init__(
        self,
        world: World,
        faults: FaultSet,
        register_map: RegisterMap | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        slow_delay_s: float = 2.0,
    ) -> None:
        self.world = world
        self.faults = faults
        self.map = register_map or RegisterMap()
        self.host = host
        self.port = port
        self.slow_delay_s = slow_delay_s
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._server: ModbusTcpServer | None = None
        self._started = threading.Event()
        self._start_error: BaseException | None = None

    @property
    def address(self) -> str:
        """"host:port" the server listens on (valid after start())."""
        return f"{self.host}:{self.port}"

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> None:
        """Listen in a background thread; returns once the port is bound."""
        if self._thread is not None:
            raise RuntimeError("simulated Modbus server already started")
        self._started.clear()
        self._thread = threading.Thread(target=self._run, name="sim-modbus", daemon=True)
        self._thread.start()
        self._started.wait(10.0)
        if self._start_error is not None or not self._started.is_set():
            self._thread.join(5.0)
            self._thread = None
            raise RuntimeError(f"simulated Modbus server could not start on {self.address}: {self._start_error}")

    def stop(self) -> None:
        """Close every connection, stop listening and join the thread (idempotent)."""
        if self._thread is None:
            return
        if self._loop is not None and self._stop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10.0)
        self._thread = None

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
        self._server = ModbusTcpServer(self._device(), address=(self.host, self.port), identity=identity)
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

    # -- datastore ------------------------------------------------------------------------
    def _device(self) -> SimDevice:
        m = self.map
        coils = [m.coils.fire_valve, m.coils.fill_valve, m.coils.vent_valve, m.coils.vacuum_pump]
        inputs = [m.discrete_inputs.door_closed, m.discrete_inputs.fixture_clamped,
                  m.discrete_inputs.estop_healthy]
        holding = [a for a in (m.holding_registers.pressure_setpoint, m.holding_registers.projectile) if a >= 0]
        input_regs = [m.input_registers.reservoir_pressure, m.input_registers.fixture_vacuum]
        return SimDevice(
            id=0,  # answer any device id, as a single controller on its own link does
            simdata=(
                [SimData(0, count=max(coils) + 1, values=False, datatype=DataType.BITS)],
                [SimData(0, count=max(inputs) + 1, values=False, datatype=DataType.BITS)],
                [SimData(0, count=max(holding) + 1, values=0, datatype=DataType.REGISTERS)],
                [SimData(0, count=max(input_regs) + 1, values=0, datatype=DataType.REGISTERS)],
            ),
            action=self._action,
        )

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
            self._close_clients()
            return ExcCodes.DEVICE_FAILURE  # never sent: the connection is gone
        if self.faults.active("modbus-slow"):
            await asyncio.sleep(self.slow_delay_s)
        if function_code in (_WRITE_COIL, _WRITE_COILS) and set_values is not None:
            for i, value in enumerate(set_values):
                self._write_coil(address + i, bool(value))
            return None
        if function_code in (_WRITE_REGISTER, _WRITE_REGISTERS) and set_values is not None:
            for i, value in enumerate(set_values):
                refused = self._write_holding(address + i, int(value))
                if refused:
                    return refused
            return None
        if function_code == _READ_COILS:
            c = self.world.coils()
            m = self.map.coils
            self._store_bits(registers, start_address, {m.fire_valve: c["fire"], m.fill_valve: c["fill"],
                                                        m.vent_valve: c["vent"], m.vacuum_pump: c["pump"]})
        elif function_code == _READ_DISCRETE:
            m = self.map.discrete_inputs
            self._store_bits(registers, start_address, {
                m.door_closed: self.world.door_closed(),
                m.fixture_clamped: self.world.fixture_clamped(),
                m.estop_healthy: self.world.estop_healthy(),
            })
        elif function_code == _READ_HOLDING:
            m = self.map.holding_registers
            scale = self.map.scales.pressure_bar_per_count
            registers[m.pressure_setpoint - start_address] = _counts(self.world.pressure_setpoint_bar(), scale)
            if m.projectile >= 0:
                registers[m.projectile - start_address] = self.world.projectile()
        elif function_code == _READ_INPUT:
            m = self.map.input_registers
            s = self.map.scales
            registers[m.reservoir_pressure - start_address] = _counts(
                self.world.reservoir_pressure_bar(), s.pressure_bar_per_count)
            registers[m.fixture_vacuum - start_address] = _counts(
                self.world.fixture_vacuum_mbar(), s.vacuum_mbar_per_count)
        return None

    def _write_coil(self, address: int, value: bool) -> None:
        m = self.map.coils
        if address == m.fire_valve:
            self.world.set_fire_valve(value)
        elif address == m.fill_valve:
            self.world.set_fill_valve(value)
        elif address == m.vent_valve:
            self.world.set_vent_valve(value)
        elif address == m.vacuum_pump:
            self.world.set_pump(value)

    def _write_holding(self, address: int, value: int) -> ExcCodes | None:
        m = self.map.holding_registers
        if address == m.pressure_setpoint:
            self.world.set_pressure_setpoint_bar(value * self.map.scales.pressure_bar_per_count)
        elif address == m.projectile and m.projectile >= 0:
            if value not in (1, 2, 3):
                return ExcCodes.ILLEGAL_VALUE
            self.world.load_projectile(value)
        return None

    @staticmethod
    def _store_bits(registers: list[int], start_register: int, bits: dict[int, bool]) -> None:
        """Set single bits in pymodbus's packed bit block (16 bits per register, bit 0 first)."""
        for bit_address, value in bits.items():
            index = bit_address // 16 - start_register
            mask = 1 << (bit_address % 16)
            registers[index] = (registers[index] | mask) if value else (registers[index] & ~mask)


def _counts(value: float, scale: float) -> int:
    """Engineering value → unsigned 16-bit register count (clipped)."""
    return int(min(max(round(value / scale), 0), UINT16_MAX))
