"""The simulated rig: the World behind three real servers, in-process or as `hopkinson sim`.

SimulatedRig starts, on loopback and a pseudo-terminal,

- the valve/vacuum controller: pymodbus TCP server (drivers/sim/modbus_server.py),
- the digitizer: SCPI socket server (drivers/sim/scpi_digitizer.py), VISA resource
  ``TCPIP0::host::port::SOCKET``,
- the bridge amplifier: serial device on a pty (drivers/sim/serial_amplifier.py),

all driven by one World (drivers/sim/world.py). Port 0 picks free ports (tests); the
`hopkinson sim` process uses the fixed ports and the pty symlink of config/sim.toml, so that
config/rig-sim.toml can point at it.

`run_simulator` is the body of the `hopkinson sim` process: it prints the three addresses,
optionally writes them as JSON, runs until SIGINT or SIGTERM, then stops the servers and
returns 0.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from hopkinson.drivers.sim.faults import FAULTS, FaultSet
from hopkinson.drivers.sim.modbus_server import SimModbusServer
from hopkinson.drivers.sim.scpi_digitizer import SimDigitizerServer
from hopkinson.drivers.sim.serial_amplifier import SimSerialAmplifier
from hopkinson.drivers.sim.world import World, WorldParams
from hopkinson.drivers.valve_controller import RegisterMap


@dataclass(frozen=True)
class ServerParams:
    """Where the simulated instruments listen (port 0 = any free port; serial_link "" = none)."""

    host: str = "127.0.0.1"
    modbus_port: int = 0
    digitizer_port: int = 0
    serial_link: str = ""
    modbus_slow_delay_s: float = 2.0


@dataclass(frozen=True)
class SimConfig:
    """Everything config/sim.toml holds."""

    world: WorldParams = field(default_factory=WorldParams)
    servers: ServerParams = field(default_factory=ServerParams)
    register_map: RegisterMap = field(default_factory=RegisterMap)


@dataclass(frozen=True)
class SimAddresses:
    """How to reach the three simulated instruments."""

    modbus_host: str
    modbus_port: int
    visa_resource: str
    serial_port: str
    serial_link: str = ""

    @property
    def modbus(self) -> str:
        return f"{self.modbus_host}:{self.modbus_port}"

    def as_dict(self) -> dict[str, Any]:
        return {
            "modbus": self.modbus,
            "modbus_host": self.modbus_host,
            "modbus_port": self.modbus_port,
            "visa_resource": self.visa_resource,
            "serial_port": self.serial_port,
            "serial_link": self.serial_link,
        }


class SimulatedRig:
    """The three simulated instruments around one World. Use as a context manager."""

    def __init__(
        self,
        config: SimConfig | None = None,
        faults: FaultSet | Iterable[str] = (),
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config or SimConfig()
        self.faults = faults if isinstance(faults, FaultSet) else FaultSet(list(faults))
        self.world = World(self.config.world, self.faults, clock=clock)
        s = self.config.servers
        self.modbus = SimModbusServer(self.world, self.faults, self.config.register_map, host=s.host,
                                      port=s.modbus_port, slow_delay_s=s.modbus_slow_delay_s)
        self.digitizer = SimDigitizerServer(self.world.capture, self.faults, host=s.host, port=s.digitizer_port)
        self.amplifier = SimSerialAmplifier(self.world, self.faults, link_path=s.serial_link or None)

    def start(self) -> None:
        """Start the three servers; if one fails, the others are stopped again."""
        try:
            self.modbus.start()
            self.digitizer.start()
            self.amplifier.start()
        except BaseException:
            self.stop()
            raise
        self.world.digitizer_armed = lambda: self.digitizer.state == "ARMED"

    def stop(self) -> None:
        """Stop every server and join its threads (idempotent)."""
        self.world.digitizer_armed = None
        for server in (self.amplifier, self.digitizer, self.modbus):
            server.stop()

    def __enter__(self) -> SimulatedRig:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def addresses(self) -> SimAddresses:
        return SimAddresses(
            modbus_host=self.modbus.host,
            modbus_port=self.modbus.port,
            visa_resource=self.digitizer.resource,
            serial_port=self.amplifier.port,
            serial_link=self.config.servers.serial_link,
        )


def fault_list_text() -> str:
    """One line per fault name, for `hopkinson sim --list-faults`."""
    width = max(len(name) for name in FAULTS)
    return "\n".join(f"{name:<{width}}  {text}" for name, text in FAULTS.items())


def write_addresses_json(path: Path, addresses: SimAddresses) -> None:
    """Write the addresses atomically (a reader never sees half a file)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    data = dict(addresses.as_dict(), pid=os.getpid())
    tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def run_simulator(
    config: SimConfig,
    faults: Iterable[str] = (),
    addresses_json: Path | None = None,
    out: TextIO = sys.stdout,
) -> int:
    """Body of the `hopkinson sim` process: serve until SIGINT/SIGTERM, then stop cleanly."""
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    rig = SimulatedRig(config, list(faults))
    try:
        rig.start()
        a = rig.addresses
        link = f" (link {a.serial_link})" if a.serial_link else ""
        out.write(f"modbus  {a.modbus}\n")
        out.write(f"visa    {a.visa_resource}\n")
        out.write(f"serial  {a.serial_port}{link}\n")
        out.write(f"faults  {', '.join(rig.faults.names()) or 'none'}\n")
        out.write("simulated rig running; Ctrl-C stops it\n")
        out.flush()
        if addresses_json is not None:
            write_addresses_json(addresses_json, a)
        while not stop.wait(0.2):
            pass
    finally:
        rig.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    out.write("simulated rig stopped\n")
    out.flush()
    return 0
