"""A Modbus instrument over TCP or RTU (serial, RS-485): the link, its errors and its limits.

`ModbusDriver` is the base of the valve/vacuum controller driver and of any Modbus instrument
a lab adds. It wraps pymodbus's synchronous clients:

- `ModbusTarget` says where the instrument is: transport "tcp" (host, port) or "rtu"
  (serial_port, baudrate, parity, stopbits, bytesize), and the unit id. Serial ports are
  opened exclusively (pymodbus passes pyserial's exclusive=True): a second process is refused.
- every transaction runs under the driver's lock (a heartbeat thread shares the link), with
  one deadline (timeout_s per attempt, `retries` re-sends) and a bounded reply: a reply longer
  than any Modbus frame (`MAX_FRAME_BYTES`) is an InstrumentError at once, never a growing
  buffer.
- every pymodbus failure becomes an InstrumentError naming the instrument, the function and
  address, and what came back (an exception code with its meaning). After a timeout or a
  dropped link the link is closed; the next call reopens it, so a late reply can never be
  taken for the answer to a later request.
- bits and registers are read per contiguous run of mapped addresses (`contiguous_runs`):
  a map with gaps never reads an unmapped address.
- with `trace` set, each request and reply PDU is traced as text.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import serial
from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from hopkinson.drivers.base import InstrumentDriver, TraceHook
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.registers import Register, RegisterRangeError, contiguous_runs

# pymodbus logs each failed request at ERROR level, with a hex dump of the last frames, before
# raising; our InstrumentErrors carry the same facts in one line. Quiet it unless the
# application has set the "pymodbus" logger's level itself (then that choice stands).
if logging.getLogger("pymodbus").level == logging.NOTSET:
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

MAX_FRAME_BYTES = 512  # an RTU frame is at most 256 bytes, a TCP ADU 260: more is not Modbus
MAX_RUN_WORDS = 125  # registers per read request (Modbus limit)
MAX_RUN_BITS = 2000  # bits per read request (Modbus limit)
EXCEPTION_MEANINGS = {
    1: "illegal function", 2: "illegal data address (not mapped in the controller)",
    3: "illegal data value", 4: "device failure (the controller refused)", 5: "acknowledge",
    6: "device busy", 8: "memory parity error", 10: "gateway path unavailable",
    11: "gateway target did not respond (wrong unit id?)",
}
PARITIES = ("N", "E", "O")
TRANSPORTS = ("tcp", "rtu")


@dataclass(frozen=True)
class ModbusTarget:
    """Where a Modbus instrument is (module docstring)."""

    transport: str = "tcp"
    host: str = ""
    port: int = 502
    serial_port: str = ""
    baudrate: int = 19200
    parity: str = "N"
    stopbits: int = 1
    bytesize: int = 8
    unit_id: int = 1

    def __post_init__(self) -> None:
        if self.transport not in TRANSPORTS:
            raise ValueError(f"Modbus transport must be 'tcp' or 'rtu', got {self.transport!r}")
        if not 0 <= self.unit_id <= 247:
            raise ValueError(f"Modbus unit id must be 0..247, got {self.unit_id}")
        if self.parity not in PARITIES:
            raise ValueError(f"parity must be N, E or O, got {self.parity!r}")

    @property
    def address(self) -> str:
        """One string for the instrument: "modbus-tcp://host:port/unit", "modbus-rtu:///dev/x/unit"."""
        if self.transport == "rtu":
            return f"modbus-rtu://{self.serial_port}/{self.unit_id}"
        return f"modbus-tcp://{self.host}:{self.port}/{self.unit_id}"

    @property
    def label(self) -> str:
        """How a person names it: "192.168.10.20:502", "/dev/ttyUSB1 unit 17"."""
        if self.transport == "rtu":
            return f"{self.serial_port} unit {self.unit_id}"
        return f"{self.host}:{self.port}" + (f" unit {self.unit_id}" if self.unit_id != 1 else "")

    @property
    def byte_time_s(self) -> float:
        """Time one byte takes on a serial line (start bit, data, parity, stop bits); 0 for TCP."""
        if self.transport != "rtu":
            return 0.0
        return (1 + self.bytesize + (self.parity != "N") + self.stopbits) / self.baudrate


class _OversizedReply(Exception):
    def __init__(self, size: int) -> None:
        super().__init__(f"reply of {size} bytes is longer than any Modbus frame ({MAX_FRAME_BYTES} bytes): "
                         "is another device or protocol on this line?")


class ModbusDriver(InstrumentDriver):
    """A Modbus instrument: life cycle, bounded transactions, reads by contiguous runs."""

    def __init__(self, target: ModbusTarget, *, timeout_s: float = 1.0, retries: int = 0,
                 name: str | None = None, trace: TraceHook | None = None) -> None:
        super().__init__(name or f"Modbus device {target.label}", timeout_s=timeout_s, trace=trace)
        if not 0 <= retries <= 10:
            raise ValueError(f"{self.name}: retries must be 0..10, got {retries}")
        self.target = target
        self.retries = retries
        self._client: ModbusTcpClient | ModbusSerialClient | None = None

    @property
    def unit_id(self) -> int:
        return self.target.unit_id

    # -- the link -------------------------------------------------------------------------------
    def _open(self) -> None:
        t = self.target
        hooks: dict[str, Any] = {"trace_packet": self._packet, "trace_pdu": self._pdu}
        client: ModbusTcpClient | ModbusSerialClient
        if t.transport == "rtu":
            client = ModbusSerialClient(t.serial_port, framer=FramerType.RTU, baudrate=t.baudrate,
                                        bytesize=t.bytesize, parity=t.parity, stopbits=t.stopbits,
                                        timeout=self.timeout_s, retries=self.retries, name=self.name, **hooks)
        else:
            client = ModbusTcpClient(t.host, port=t.port, timeout=self.timeout_s, retries=self.retries,
                                     name=self.name, **hooks)
        if not client.connect():
            client.close()
            raise InstrumentConnectionError(self.name, "connect", self._why_not_connected())
        self._client = client

    def _why_not_connected(self) -> str:
        if self.target.transport != "rtu":
            return f"could not connect to {self.target.host}:{self.target.port} (nothing listening?)"
        try:  # pymodbus logs the reason and returns False: open the port once to learn it
            serial.Serial(self.target.serial_port, exclusive=True).close()
        except (serial.SerialException, OSError, ValueError) as exc:
            busy = "lock" in str(exc).lower()
            hint = " (held by another process: see `hopkinson status`)" if busy else ""
            return f"cannot open serial port {self.target.serial_port}: {exc}{hint}"
        return f"cannot open serial port {self.target.serial_port}"

    def _close_link(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            client.close()

    def _link_open(self) -> bool:
        return self._client is not None

    def _packet(self, sending: bool, data: bytes) -> bytes:
        if not sending and len(data) > MAX_FRAME_BYTES:
            raise _OversizedReply(len(data))
        return data

    def _pdu(self, sending: bool, pdu: Any) -> Any:
        if self.trace is not None:
            self._trace("->" if sending else "<-", str(pdu))
        return pdu

    # -- transactions ---------------------------------------------------------------------------
    def call(self, command: str, request: Callable[[Any], Any]) -> Any:
        """Run one request under the lock; every failure becomes an InstrumentError naming it."""
        with self.lock:
            self._ensure_link(command)
            assert self._client is not None
            try:
                response = request(self._client)
            except _OversizedReply as exc:
                self._drop()
                raise InstrumentError(self.name, command, str(exc)) from None
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
            except (OSError, serial.SerialException) as exc:
                self._drop()
                raise InstrumentConnectionError(self.name, command, f"link error: {exc}") from exc
        if response is None:
            raise InstrumentError(self.name, command, "no response object")
        if response.isError():
            code = getattr(response, "exception_code", None)
            meaning = EXCEPTION_MEANINGS.get(code, "exception") if isinstance(code, int) else "error"
            raise ModbusRefusal(self.name, command, f"Modbus exception {code}: {meaning}", str(response), code)
        return response

    def read_bits(self, table: str, addresses: Iterable[int]) -> dict[int, bool]:
        """Bits of "coils" or "discrete inputs" at `addresses`, read run by run."""
        function = {"coils": "read_coils", "discrete inputs": "read_discrete_inputs"}[table]
        return {a: bool(v) for a, v in self._read_runs(table, function, addresses, MAX_RUN_BITS, "bits").items()}

    def read_words(self, table: str, addresses: Iterable[int]) -> dict[int, int]:
        """16-bit words of "holding registers" or "input registers", read run by run."""
        function = {"holding registers": "read_holding_registers", "input registers": "read_input_registers"}[table]
        return {a: int(v) for a, v in self._read_runs(table, function, addresses, MAX_RUN_WORDS, "registers").items()}

    def _read_runs(self, table: str, function: str, addresses: Iterable[int], limit: int, field: str) -> dict[int, Any]:
        out: dict[int, Any] = {}
        for start, count in _split(contiguous_runs(addresses), limit):
            command = f"read {table} {_span(start, count)}"
            response = self.call(command, lambda c, s=start, n=count: getattr(c, function)(
                s, count=n, device_id=self.unit_id))
            values = list(getattr(response, field))
            if len(values) < count:  # bits come in whole bytes: never fewer than asked
                raise InstrumentError(self.name, command, "short reply", str(values))
            out.update({start + i: values[i] for i in range(count)})
        return out

    def read_values(self, table: str, registers: dict[str, Register]) -> dict[str, float]:
        """Engineering values of typed registers (one request per contiguous run)."""
        words = self.read_words(table, [a for r in registers.values() for a in r.addresses])
        return {name: r.decode([words[a] for a in r.addresses]) for name, r in registers.items()}

    def write_coil(self, address: int, value: bool, what: str) -> None:
        self.call(f"write coil {address} ({what}) = {bool(value)}",
                  lambda c: c.write_coil(address, bool(value), device_id=self.unit_id))

    def write_word(self, address: int, value: int, what: str) -> None:
        """One uint16 holding register (a code, not a scaled value)."""
        if not 0 <= value <= 0xFFFF:
            raise ValueError(f"{self.name}: {what} {value} does not fit a 16-bit register")
        self.call(f"write register {address} ({what}) = {value}",
                  lambda c: c.write_register(address, value, device_id=self.unit_id))

    def write_value(self, register: Register, value: float, what: str, unit: str = "") -> None:
        """A typed, scaled holding register (ValueError naming it when it cannot hold `value`)."""
        try:
            words = register.encode(value)
        except RegisterRangeError as exc:
            raise ValueError(f"{self.name}: {what} {value:g} {unit}: {exc}".replace("  ", " ")) from None
        command = f"write register {_span(register.address, len(words))} ({what}) = {words}"
        if len(words) == 1:
            self.call(command, lambda c: c.write_register(register.address, words[0], device_id=self.unit_id))
        else:
            self.call(command, lambda c: c.write_registers(register.address, words, device_id=self.unit_id))


class ModbusRefusal(InstrumentError):
    """The instrument answered with a Modbus exception (`code`: its exception code)."""

    def __init__(self, instrument: str, command: str, problem: str, reply: str, code: int | None) -> None:
        super().__init__(instrument, command, problem, reply)
        self.code = code


def _span(start: int, count: int) -> str:
    return str(start) if count == 1 else f"{start}..{start + count - 1}"


def _split(runs: list[tuple[int, int]], limit: int) -> list[tuple[int, int]]:
    """Runs no longer than one request may read."""
    out = []
    for start, count in runs:
        for offset in range(0, count, limit):
            out.append((start + offset, min(limit, count - offset)))
    return out
