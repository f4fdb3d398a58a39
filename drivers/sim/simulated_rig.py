"""The simulated rig: the World behind three real servers, in-process or as `hopkinson sim`.

SimulatedRig starts, on loopback and pseudo-terminals,

- the valve/vacuum controller: pymodbus server, Modbus TCP or Modbus RTU on a simulated serial
  line (drivers/sim/modbus_server.py),
- the digitizer: SCPI socket server (drivers/sim/scpi_digitizer.py), VISA resource
  ``TCPIP0::host::port::SOCKET``, in the dialect of `ServerParams.digitizer_dialect` (generic,
  keysight, tektronix or lecroy); the world's Doppler beat is on its channel 1, the response
  on channel 2 (`DIGITIZER_CHANNELS`), and when the world makes them the quadrature
  photodetector on 3 and a second sensor on 4 (`WorldParams.channels()`, in the addresses),
- the bridge amplifier: serial device on a simulated line at its baud rate
  (drivers/sim/serial_amplifier.py),

all driven by one World (drivers/sim/world.py). Port 0 picks free ports (tests); the
`hopkinson sim` process uses the ports of config/sim.toml.

`run_simulator` is the body of the `hopkinson sim` process: it prints the addresses, writes
them as JSON to the per-user runtime folder (`sim-addresses.json`: config/rig-sim.toml's
``"sim:amplifier"`` and ``"sim:controller"`` ports are looked up there), names its ptys there
(`sim-<pid>-amplifier`, `sim-<pid>-controller`: unique per instance), writes its state there
every `STATE_PERIOD_S` (`sim-<pid>-state.json`: commanded coils, real valve positions,
pressures, watchdog), runs until SIGINT or SIGTERM, then stops the servers, removes what it
named and returns 0. Every file is written atomically (hopkinson.fileio).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, TextIO

from pydantic import Field

from hopkinson.drivers.sim.config_fields import (
    SECTION,
    Baud,
    Int,
    Number,
    Parity,
    StopBits,
    Transport,
)
from hopkinson.drivers.sim.controller_map import FIRE_STYLES, ControllerMap, default_map
from hopkinson.drivers.sim.faults import FAULTS, FaultSet
from hopkinson.drivers.sim.modbus_server import SimModbusServer
from hopkinson.drivers.sim.scpi_digitizer import SIM_DIALECTS, SimDigitizerServer
from hopkinson.drivers.sim.serial_amplifier import SimSerialAmplifier
from hopkinson.drivers.sim.world import World, WorldParams
from hopkinson.fileio import atomic_write, private_runtime_dir

ADDRESSES_FILE = "sim-addresses.json"  # in the runtime folder: the running `hopkinson sim`
STATE_PERIOD_S = 0.2
DIGITIZER_CHANNELS = {"doppler": 1, "response": 2}  # role -> channel number (World.capture)
SimFireStyle = Literal[FIRE_STYLES]  # type: ignore[valid-type]  # controller_map.FIRE_STYLES
SimDialect = Literal[tuple(SIM_DIALECTS)]  # type: ignore[valid-type]  # generic | keysight | tektronix | lecroy


@dataclass(frozen=True)
class ServerParams:
    """[servers] of config/sim.toml: how the simulated instruments are reached (port 0 = any free port)."""

    __pydantic_config__ = SECTION
    host: str = "127.0.0.1"
    modbus_transport: Annotated[Transport, Field(description="the controller on Modbus TCP, or RTU on a "
                                                             "simulated serial line")] = "tcp"
    modbus_port: Annotated[Int, Field(ge=0, le=65535, description="TCP port; 0 = any free port")] = 0
    modbus_unit_id: Annotated[Int, Field(ge=1, le=247, description="the controller answers only this unit id")] = 1
    modbus_baudrate: Baud = 19200
    modbus_parity: Parity = "N"
    modbus_stopbits: StopBits = 1
    digitizer_port: Annotated[Int, Field(ge=0, le=65535, description="SCPI socket; 0 = any free port")] = 0
    digitizer_dialect: Annotated[SimDialect, Field(description="the simulated digitizer's command set")] = "generic"
    amplifier_baudrate: Baud = 115200
    modbus_slow_delay_s: Annotated[Number, Field(ge=0, le=60, description="reply delay under the modbus-slow "
                                                                          "fault")] = 2.0
    modbus_fire_style: Annotated[SimFireStyle, Field(description="how the simulated PLC fires "
                                                                 "(docs/plc-fire-styles.md)")] = "pulse_register"
    modbus_fire_preset_ms: Annotated[Number, Field(gt=0, le=60_000, description=(
        "the PLC's own pulse preset, ms (the preset and preset-coil styles)"))] = 150.0
    modbus_fire_command_value: Annotated[Int, Field(ge=1, le=65535, description=(
        "preset_and_command: the command word that fires"))] = 1


@dataclass(frozen=True)
class SimConfig:
    """Everything config/sim.toml holds."""

    world: WorldParams = field(default_factory=WorldParams)
    servers: ServerParams = field(default_factory=ServerParams)
    register_map: ControllerMap = field(default_factory=default_map)


@dataclass(frozen=True)
class SimAddresses:
    """How to reach the three simulated instruments.

    modbus: "host:port" (TCP) or the pty path (RTU); serial_port: the amplifier's pty;
    digitizer_dialect and digitizer_channels (role -> channel number): how the digitizer speaks
    and where it has each signal."""

    modbus_host: str
    modbus_port: int
    visa_resource: str
    serial_port: str
    modbus_transport: str = "tcp"
    modbus_serial_port: str = ""
    modbus_unit_id: int = 1
    modbus_baudrate: int = 19200
    modbus_parity: str = "N"
    modbus_stopbits: int = 1
    amplifier_baudrate: int = 115200
    digitizer_dialect: str = "generic"
    digitizer_channels: dict[str, int] = field(default_factory=lambda: dict(DIGITIZER_CHANNELS))

    @property
    def modbus(self) -> str:
        if self.modbus_transport == "rtu":
            return self.modbus_serial_port
        return f"{self.modbus_host}:{self.modbus_port}"

    def as_dict(self) -> dict[str, Any]:
        return {
            "modbus": self.modbus,
            "modbus_transport": self.modbus_transport,
            "modbus_host": self.modbus_host,
            "modbus_port": self.modbus_port,
            "modbus_serial_port": self.modbus_serial_port,
            "modbus_unit_id": self.modbus_unit_id,
            "modbus_baudrate": self.modbus_baudrate,
            "modbus_parity": self.modbus_parity,
            "modbus_stopbits": self.modbus_stopbits,
            "visa_resource": self.visa_resource,
            "digitizer_dialect": self.digitizer_dialect,
            "digitizer_channels": dict(self.digitizer_channels),
            "serial_port": self.serial_port,
            "amplifier_baudrate": self.amplifier_baudrate,
        }


class SimulatedRig:
    """The three simulated instruments around one World. Use as a context manager."""

    def __init__(
        self,
        config: SimConfig | None = None,
        faults: FaultSet | Iterable[str] = (),
        clock: Callable[[], float] = time.monotonic,
        link_prefix: str = "",
    ) -> None:
        """link_prefix: when given, the ptys are also reachable as `<prefix>amplifier` and
        (RTU) `<prefix>controller` (symlinks)."""
        self.config = config or SimConfig()
        self.faults = faults if isinstance(faults, FaultSet) else FaultSet(list(faults))
        self.world = World(self.config.world, self.faults, clock=clock)
        s = self.config.servers
        self.modbus = SimModbusServer(
            self.world, self.faults, self.config.register_map, transport=s.modbus_transport,
            unit_id=s.modbus_unit_id, host=s.host, port=s.modbus_port, baudrate=s.modbus_baudrate,
            parity=s.modbus_parity, stopbits=s.modbus_stopbits,
            serial_link=f"{link_prefix}controller" if link_prefix else "", slow_delay_s=s.modbus_slow_delay_s,
            fire_style=s.modbus_fire_style, fire_preset_ms=s.modbus_fire_preset_ms,
            fire_command_value=s.modbus_fire_command_value)
        self.digitizer = SimDigitizerServer(self.world.capture, self.faults, host=s.host, port=s.digitizer_port,
                                            dialect=s.digitizer_dialect)
        self.amplifier = SimSerialAmplifier(self.world, self.faults, baudrate=s.amplifier_baudrate,
                                            link_path=f"{link_prefix}amplifier" if link_prefix else None)

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
        s = self.config.servers
        rtu = s.modbus_transport == "rtu"
        return SimAddresses(
            modbus_host=self.modbus.host,
            modbus_port=0 if rtu else self.modbus.port,
            visa_resource=self.digitizer.resource,
            serial_port=self.amplifier.port,
            modbus_transport=s.modbus_transport,
            modbus_serial_port=self.modbus.address if rtu else "",
            modbus_unit_id=s.modbus_unit_id,
            modbus_baudrate=s.modbus_baudrate,
            modbus_parity=s.modbus_parity,
            modbus_stopbits=s.modbus_stopbits,
            amplifier_baudrate=s.amplifier_baudrate,
            digitizer_dialect=self.digitizer.dialect,
            digitizer_channels=self.config.world.channels(),
        )

    def state(self) -> dict[str, Any]:
        """The rig as it is: what the valves were told and where they really are, pressures,
        interlocks, watchdog, shots, and the digitizer's acquisition state (JSON-ready)."""
        return {**world_state(self.world), "digitizer_state": self.digitizer.state}


def world_state(world: World) -> dict[str, Any]:
    """The simulated rig's state. `*_valve_open` is the valve's real position (a stuck fill
    valve is open whatever it was told); `*_valve_commanded` is its coil."""
    coils = world.coils()
    positions = world.valve_positions()
    return {
        "fire_valve_open": positions["fire"],
        "fill_valve_open": positions["fill"],
        "vent_valve_open": positions["vent"],
        "fire_valve_commanded": coils["fire"],
        "fill_valve_commanded": coils["fill"],
        "vent_valve_commanded": coils["vent"],
        "vacuum_pump_on": coils["pump"],
        "reservoir_pressure_bar": world.reservoir_pressure_bar(),
        "pressure_setpoint_bar": world.pressure_setpoint_bar(),
        "fixture_vacuum_mbar": world.fixture_vacuum_mbar(),
        "door_closed": world.door_closed(),
        "estop_healthy": world.estop_healthy(),
        "watchdog": world.watchdog_state(),
        "watchdog_trips": world.watchdog_trips,
        "watchdog_tripped_at_sim_s": world.watchdog_tripped_at_sim_s,
        "fire_pulses": world.fire_pulses,
        "shots_fired": world.shots_fired,
        "fire_refusals": list(world.fire_refusals),
        "faults": world.faults.names(),
        "sim_time_s": world.sim_time_s(),
    }


def write_state_file(path: Path, state: dict[str, Any]) -> None:
    """Write the state JSON atomically (a reader never sees half a file)."""
    atomic_write(path, json.dumps(state, indent=2) + "\n")


def fault_list_text() -> str:
    """One line per fault name, for `hopkinson sim --list-faults`."""
    width = max(len(name) for name in FAULTS)
    return "\n".join(f"{name:<{width}}  {text}" for name, text in FAULTS.items())


def write_addresses_json(path: Path, addresses: SimAddresses, **extra: Any) -> None:
    """Write the addresses atomically (a reader never sees half a file)."""
    data = dict(addresses.as_dict(), pid=os.getpid(), **extra)
    atomic_write(path, json.dumps(data, indent=2) + "\n")


def read_running_addresses(runtime_dir: Path | None = None) -> dict[str, Any] | None:
    """The addresses of this user's running `hopkinson sim` (None when none is running)."""
    path = (runtime_dir or private_runtime_dir()) / ADDRESSES_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    pid = data.get("pid") if isinstance(data, dict) else None
    if not isinstance(pid, int) or not _alive(pid):
        return None
    return data


def remove_stale_files(runtime: Path) -> list[Path]:
    """Remove what a `hopkinson sim` that was killed (SIGKILL: no clean-up of its own) left in
    the runtime folder: its pty links and state file (sim-<pid>-*) and a published address file
    naming it; returns the paths removed."""
    removed: list[Path] = []
    for path in runtime.glob("sim-*-*"):
        pid = path.name.split("-")[1]
        if pid.isdigit() and not _alive(int(pid)):
            with contextlib.suppress(OSError):
                path.unlink()
                removed.append(path)
    published = runtime / ADDRESSES_FILE
    with contextlib.suppress(OSError, ValueError, AttributeError):
        pid = json.loads(published.read_text(encoding="utf-8")).get("pid")
        if isinstance(pid, int) and not _alive(pid):
            published.unlink()
            removed.append(published)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def run_simulator(
    config: SimConfig,
    faults: Iterable[str] = (),
    addresses_json: Path | None = None,
    out: TextIO = sys.stdout,
    runtime_dir: Path | None = None,
    notes: Callable[[SimAddresses], list[str]] | None = None,
) -> int:
    """Body of the `hopkinson sim` process (module docstring): serve until SIGINT/SIGTERM.
    `notes(addresses)`: lines printed under the digitizer's address (the rig config it needs)."""
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set())
                for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    runtime = runtime_dir or private_runtime_dir()
    remove_stale_files(runtime)
    prefix = str(runtime / f"sim-{os.getpid()}-")
    state_path = Path(prefix + "state.json")
    published = runtime / ADDRESSES_FILE
    rig = SimulatedRig(config, list(faults), link_prefix=prefix)
    try:
        rig.start()
        a = rig.addresses
        modbus = f"modbus  {a.modbus_transport} {a.modbus} (unit {a.modbus_unit_id})"
        if a.modbus_transport == "rtu":
            modbus += f", link {prefix}controller"
        out.write(modbus + "\n")
        out.write(f'        fire_style = "{config.servers.modbus_fire_style}" (docs/plc-fire-styles.md)\n')
        channels = ", ".join(f"{role} on channel {n}" for role, n in a.digitizer_channels.items())
        out.write(f"visa    {a.visa_resource}\n")
        out.write(f"        {a.digitizer_dialect} dialect: {channels}\n")
        for line in notes(a) if notes is not None else ():
            out.write(f"        {line}\n")
        out.write(f"serial  {a.serial_port} (link {prefix}amplifier)\n")
        out.write(f"state   {state_path}\n")
        out.write(f"faults  {', '.join(rig.faults.names()) or 'none'}\n")
        out.write("simulated rig running; Ctrl-C stops it\n")
        out.flush()
        write_state_file(state_path, rig.state())
        for path in (published, addresses_json):
            if path is not None:
                write_addresses_json(path, a, state_file=str(state_path))
        while not stop.wait(STATE_PERIOD_S):
            write_state_file(state_path, rig.state())  # also applies a watchdog trip on time
    finally:
        rig.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        with contextlib.suppress(OSError, ValueError):
            if json.loads(published.read_text(encoding="utf-8")).get("pid") == os.getpid():
                published.unlink()
        with contextlib.suppress(OSError):
            state_path.unlink()
    out.write("simulated rig stopped\n")
    out.flush()
    return 0
