"""Gas valve / vacuum controller of the Hopkinson bar, over Modbus TCP (pymodbus).

The controller (a PLC or a remote-I/O box) exposes:

- coils: fire valve, fill valve, vent valve, vacuum pump (True = open / running);
- a holding register: the reservoir pressure set-point (scaled integer);
- input registers: reservoir pressure and fixture vacuum (scaled integers);
- discrete inputs: door/guard closed, fixture clamped, e-stop healthy (True = safe).

Register numbers (0-based protocol addresses) and scale factors differ from lab to lab: they
come from `config/rig.toml` as a :class:`RegisterMap`. Pressures are gauge pressures in bar
(0 = ambient); the fixture vacuum is an absolute pressure in mbar (≈1013 = no vacuum).

Fill-valve regulation lives in the controller: while the fill coil is on, the controller
fills the reservoir up to the set-point and holds it there (the coil stays as commanded).
The rig still watches the pressure and closes the fill coil itself; a controller without
regulation only needs the rig's watch.

Errors name the instrument, the Modbus function and address, and what came back. After a
timeout or a dropped connection the socket is closed; the next call reconnects, so a late
reply can never be taken for the answer to a later request (inside `with`, the next call
reconnects by itself).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

UINT16_MAX = 0xFFFF

# pymodbus logs each failed request at ERROR level, with a hex dump of the last frames, before
# raising; our InstrumentErrors carry the same facts in one line. Quiet it unless the
# application has set the "pymodbus" logger's level itself (then that choice stands).
if logging.getLogger("pymodbus").level == logging.NOTSET:
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


@dataclass(frozen=True)
class CoilMap:
    """Coil addresses (0-based) of the four actuators."""

    fire_valve: int = 0
    fill_valve: int = 1
    vent_valve: int = 2
    vacuum_pump: int = 3


@dataclass(frozen=True)
class DiscreteInputMap:
    """Discrete-input addresses (0-based) of the interlocks; each input is True when safe."""

    door_closed: int = 0
    fixture_clamped: int = 1
    estop_healthy: int = 2


@dataclass(frozen=True)
class HoldingRegisterMap:
    """Holding-register addresses (0-based).

    projectile: the projectile type loaded (1..3) as entered on the controller's panel;
    -1 when the controller has no such register (then `set_projectile` is refused).
    """

    pressure_setpoint: int = 0
    projectile: int = 1


@dataclass(frozen=True)
class InputRegisterMap:
    """Input-register addresses (0-based) of the two gauges."""

    reservoir_pressure: int = 0
    fixture_vacuum: int = 1


@dataclass(frozen=True)
class ScaleMap:
    """Engineering units per register count (unsigned 16-bit registers)."""

    pressure_bar_per_count: float = 0.001
    vacuum_mbar_per_count: float = 0.1


@dataclass(frozen=True)
class RegisterMap:
    """Where every signal of the controller lives, and how its integers scale."""

    coils: CoilMap = field(default_factory=CoilMap)
    discrete_inputs: DiscreteInputMap = field(default_factory=DiscreteInputMap)
    holding_registers: HoldingRegisterMap = field(default_factory=HoldingRegisterMap)
    input_registers: InputRegisterMap = field(default_factory=InputRegisterMap)
    scales: ScaleMap = field(default_factory=ScaleMap)


@dataclass(frozen=True)
class ValveStates:
    """Commanded states of the actuators (coil values)."""

    fire_valve: bool
    fill_valve: bool
    vent_valve: bool
    vacuum_pump: bool


@dataclass(frozen=True)
class Interlocks:
    """Interlock inputs, each True when safe."""

    door_closed: bool
    fixture_clamped: bool
    estop_healthy: bool

    @property
    def all_safe(self) -> bool:
        return self.door_closed and self.fixture_clamped and self.estop_healthy

    def problems(self) -> list[str]:
        """Plain-language list of the interlocks that are not safe."""
        out = []
        if not self.door_closed:
            out.append("door/guard open")
        if not self.fixture_clamped:
            out.append("fixture not clamped")
        if not self.estop_healthy:
            out.append("e-stop tripped")
        return out


@dataclass(frozen=True)
class ControllerStatus:
    """Everything the controller reports, read in one go."""

    reservoir_pressure_bar: float
    pressure_setpoint_bar: float
    fixture_vacuum_mbar: float
    valves: ValveStates
    interlocks: Interlocks


class ValveController:
    """Driver of the gas valve / vacuum controller (Modbus TCP).

    Use as a context manager: `with ValveController(host, port) as vc: vc.status()`.
    """

    def __init__(
        self,
        host: str,
        port: int = 502,
        *,
        device_id: int = 1,
        timeout_s: float = 1.0,
        retries: int = 0,
        register_map: RegisterMap | None = None,
        name: str | None = None,
    ) -> None:
        if not 0 <= device_id <= 247:
            raise ValueError(f"Modbus device id must be 0..247, got {device_id}")
        if timeout_s <= 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s}")
        self.host = host
        self.port = port
        self.device_id = device_id
        self.timeout_s = timeout_s
        self.retries = retries
        self.map = register_map or RegisterMap()
        self.name = name or f"valve controller {host}:{port}"
        self._client: ModbusTcpClient | None = None
        self._wanted = False  # connect() called and close() not: reconnect after a failure

    # -- connection ---------------------------------------------------------------------
    def connect(self) -> None:
        """Open the TCP connection; InstrumentConnectionError when nobody answers."""
        self._drop()
        client = ModbusTcpClient(
            self.host, port=self.port, timeout=self.timeout_s, retries=self.retries, name=self.name
        )
        if not client.connect():
            client.close()
            raise InstrumentConnectionError(self.name, "connect", "could not connect (nothing listening?)")
        self._client = client
        self._wanted = True

    def close(self) -> None:
        """Close the connection (idempotent)."""
        self._drop()
        self._wanted = False

    def _drop(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def __enter__(self) -> ValveController:
        self.connect()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # -- identity -----------------------------------------------------------------------
    def identity(self) -> str:
        """Vendor, product code and revision (Modbus 'read device identification', basic)."""
        response = self._call("read device identification", lambda c: c.read_device_information(
            read_code=0x01, object_id=0x00, device_id=self.device_id))
        info = getattr(response, "information", {}) or {}
        parts = []
        for key in (0x00, 0x01, 0x02):
            value = info.get(key, b"")
            parts.append(value.decode("ascii", "replace") if isinstance(value, bytes) else str(value))
        return ",".join(parts)

    # -- actuators ----------------------------------------------------------------------
    def set_fire_valve(self, open_: bool) -> None:
        """Open (fires the projectile) or close the fire valve."""
        self._write_coil(self.map.coils.fire_valve, open_, "fire valve")

    def set_fill_valve(self, open_: bool) -> None:
        """Open the fill valve (the controller fills up to the set-point) or close it."""
        self._write_coil(self.map.coils.fill_valve, open_, "fill valve")

    def set_vent_valve(self, open_: bool) -> None:
        """Open (reservoir vents to ambient) or close the vent valve."""
        self._write_coil(self.map.coils.vent_valve, open_, "vent valve")

    def set_vacuum_pump(self, on: bool) -> None:
        """Start or stop the fixture vacuum pump."""
        self._write_coil(self.map.coils.vacuum_pump, on, "vacuum pump")

    def valves(self) -> ValveStates:
        """Commanded states of the four actuators (coils read back)."""
        c = self.map.coils
        bits = self._read_bits("read coils", [c.fire_valve, c.fill_valve, c.vent_valve, c.vacuum_pump])
        return ValveStates(*bits)

    def set_pressure_setpoint_bar(self, pressure_bar: float) -> None:
        """Reservoir pressure set-point (gauge bar); must fit the scaled register."""
        scale = self.map.scales.pressure_bar_per_count
        self._write_register(self.map.holding_registers.pressure_setpoint, pressure_bar, scale,
                             "pressure set-point", "bar")

    def pressure_setpoint_bar(self) -> float:
        """The set-point as the controller holds it (gauge bar)."""
        address = self.map.holding_registers.pressure_setpoint
        (count,) = self._read_registers("read holding registers", address, 1)
        return count * self.map.scales.pressure_bar_per_count

    def set_projectile(self, projectile: int) -> None:
        """Tell the controller which projectile type (1..3) is loaded."""
        if projectile not in (1, 2, 3):
            raise ValueError(f"projectile must be 1, 2 or 3, got {projectile}")
        address = self.map.holding_registers.projectile
        if address < 0:
            raise InstrumentError(self.name, "set projectile", "this controller has no projectile register")
        self._call(f"write register {address}={projectile}",
                   lambda c: c.write_register(address, projectile, device_id=self.device_id))

    # -- gauges and interlocks ----------------------------------------------------------
    def reservoir_pressure_bar(self) -> float:
        """Reservoir gauge pressure in bar."""
        (count,) = self._read_registers("read input registers", self.map.input_registers.reservoir_pressure, 1)
        return count * self.map.scales.pressure_bar_per_count

    def fixture_vacuum_mbar(self) -> float:
        """Absolute pressure in the vacuum fixture, mbar (lower is a better vacuum)."""
        (count,) = self._read_registers("read input registers", self.map.input_registers.fixture_vacuum, 1)
        return count * self.map.scales.vacuum_mbar_per_count

    def interlocks(self) -> Interlocks:
        """Door, clamp and e-stop inputs (True = safe)."""
        d = self.map.discrete_inputs
        bits = self._read_bits("read discrete inputs", [d.door_closed, d.fixture_clamped, d.estop_healthy])
        return Interlocks(*bits)

    def status(self) -> ControllerStatus:
        """Pressures, vacuum, valve states and interlocks."""
        return ControllerStatus(
            reservoir_pressure_bar=self.reservoir_pressure_bar(),
            pressure_setpoint_bar=self.pressure_setpoint_bar(),
            fixture_vacuum_mbar=self.fixture_vacuum_mbar(),
            valves=self.valves(),
            interlocks=self.interlocks(),
        )

    # -- protocol helpers ---------------------------------------------------------------
    def _write_coil(self, address: int, value: bool, what: str) -> None:
        self._call(f"write coil {address} ({what})={bool(value)}",
                   lambda c: c.write_coil(address, bool(value), device_id=self.device_id))

    def _write_register(self, address: int, value: float, scale: float, what: str, unit: str) -> None:
        count = round(value / scale)
        if not 0 <= count <= UINT16_MAX:
            high = UINT16_MAX * scale
            raise ValueError(f"{self.name}: {what} {value} {unit} outside the register range 0..{high:g} {unit}")
        self._call(f"write register {address} ({what})={count}",
                   lambda c: c.write_register(address, count, device_id=self.device_id))

    # `function` is the Modbus function as errors name it; its words are the pymodbus client
    # method ("read coils" -> read_coils).
    def _read_bits(self, function: str, addresses: list[int]) -> list[bool]:
        start, stop = min(addresses), max(addresses)
        response = self._call(f"{function} {start}..{stop}", lambda c: getattr(c, function.replace(" ", "_"))(
            start, count=stop - start + 1, device_id=self.device_id))
        bits = list(response.bits)
        if len(bits) < stop - start + 1:
            raise InstrumentError(self.name, f"{function} {start}..{stop}", "short reply", str(bits))
        return [bool(bits[a - start]) for a in addresses]

    def _read_registers(self, function: str, address: int, count: int) -> list[int]:
        response = self._call(f"{function} {address}", lambda c: getattr(c, function.replace(" ", "_"))(
            address, count=count, device_id=self.device_id))
        registers = list(response.registers)
        if len(registers) != count:
            raise InstrumentError(self.name, f"{function} {address}", "short reply", str(registers))
        return registers

    def _call(self, command: str, request: Any) -> Any:
        """Run one request; turn every pymodbus failure into an InstrumentError naming it."""
        if self._client is None:
            if not self._wanted:
                raise InstrumentConnectionError(self.name, command, "not connected (use `with` or connect())")
            self.connect()  # the last request failed: start afresh on a new connection
        assert self._client is not None
        try:
            response = request(self._client)
        except ConnectionException as exc:
            self._drop()
            raise InstrumentConnectionError(self.name, command, f"connection lost: {exc}") from exc
        except ModbusIOException as exc:
            self._drop()
            text = str(exc)
            if "No response" in text or "timeout" in text.lower():
                raise InstrumentTimeout(self.name, command, f"no reply within {self.timeout_s:g} s") from exc
            raise InstrumentConnectionError(self.name, command, f"connection lost: {text}") from exc
        except ModbusException as exc:
            self._drop()
            raise InstrumentError(self.name, command, f"Modbus failure: {exc}") from exc
        except OSError as exc:
            self._drop()
            raise InstrumentConnectionError(self.name, command, f"socket error: {exc}") from exc
        if response is None:
            raise InstrumentError(self.name, command, "no response object")
        if response.isError():
            code = getattr(response, "exception_code", "?")
            raise InstrumentError(self.name, command, f"controller refused (Modbus exception code {code})",
                                  str(response))
        return response

