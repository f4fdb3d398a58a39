"""The rig's three instruments, built from a RigConfig by their configured drivers, opened
together as one context.

    with open_instruments(config) as instruments:
        sequencer = Sequencer(instruments, config, bus)

Each `[valve_controller]`, `[digitizer]`, `[amplifier]` section names its driver: a built-in
one (below), "package.module:Class" or an entry point (rig/driver_classes.py). A built-in
driver is made from the section's typed keys; a lab's class gets the section's `options`
table as keyword arguments, and the object is checked against its role (drivers/roles.py).

A serial port written ``"sim:amplifier"`` or ``"sim:controller"`` is the port of this user's
running `hopkinson sim` (its addresses file in the private runtime folder).

`open_instruments` connects the controller, the digitizer and the amplifier in that order;
if one cannot be reached, the ones already open are closed again and the InstrumentError
(naming the instrument) propagates. On leaving the context every instrument is closed.

`sim_rig_config` makes a RigConfig that reaches a running SimulatedRig (in-process, on free
ports): its addresses, register map, fire style and digitizer dialect and channels, everything
else from the given base configuration.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hopkinson.drivers.base import TraceHook
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError
from hopkinson.drivers.roles import (
    ROLES,
    AmplifierRole,
    DigitizerRole,
    ValveControllerRole,
    missing_members,
)
from hopkinson.rig.config import (
    AmplifierConfig,
    DigitizerConfig,
    RigConfig,
    ValveControllerConfig,
    register_map_of,
    register_tables,
)
from hopkinson.rig.driver_classes import driver_class
from hopkinson.rig.errors import ConfigError

if TYPE_CHECKING:
    from hopkinson.drivers.sim.simulated_rig import SimConfig, SimulatedRig

SIM_PORT_PREFIX = "sim:"
SIM_PORTS = {"sim:amplifier": "serial_port", "sim:controller": "modbus_serial_port"}
# A digitizer role beyond the first two, and the role whose range it takes when it names none.
PARTNERS = {"doppler_quadrature": "doppler", "response_2": "response"}


@dataclass
class Instruments:
    """The three connected drivers; `simulated_truth` returns the simulator's truth of the
    last shot (None on a real rig)."""

    valves: ValveControllerRole
    digitizer: DigitizerRole
    amplifier: AmplifierRole
    simulated_truth: Callable[[], dict[str, Any] | None] | None = None

    def each(self) -> dict[str, Any]:
        """role name -> driver."""
        return {"valve_controller": self.valves, "digitizer": self.digitizer, "amplifier": self.amplifier}

    def identities(self) -> dict[str, str]:
        """name -> identity string of each instrument; an unanswered query is noted, not raised
        (Modbus device identification is optional)."""
        out: dict[str, str] = {}
        for key, instrument in self.each().items():
            try:
                out[key] = instrument.identity()
            except InstrumentError as exc:
                out[key] = f"(no identification: {exc.problem})"
        return out

    def set_trace(self, hook: TraceHook | None) -> None:
        """Send every instrument exchange to `hook` (None: stop)."""
        for instrument in self.each().values():
            instrument.trace = hook

    def close(self) -> None:
        """Close all three (idempotent; never raises)."""
        for instrument in (self.amplifier, self.digitizer, self.valves):
            with contextlib.suppress(Exception):
                instrument.close()


# -- built-in drivers ---------------------------------------------------------------------------
def _modbus_controller(config: RigConfig) -> ValveControllerRole:
    from hopkinson.drivers.valve_controller import ValveController

    vc = config.valve_controller
    target = vc.target
    if target.transport == "rtu":
        target = dataclasses.replace(target, serial_port=resolve_port(vc.serial_port, "valve controller"))
    return ValveController(target, register_map=vc.register_map, timeout_s=vc.timeout_s, retries=vc.retries,
                           watchdog_s=vc.watchdog_s, fire_style=vc.fire_style,
                           fire_command_value=vc.fire_command_value,
                           host_timed_fire_allowed=vc.host_timed_fire_allowed)


def _serial_bridge(config: RigConfig) -> AmplifierRole:
    from hopkinson.drivers.amplifier import BridgeAmplifier

    amp = config.amplifier
    return BridgeAmplifier(resolve_port(amp.port, "bridge amplifier"), baudrate=amp.baudrate,
                           timeout_s=amp.timeout_s, retries=amp.retries)


def _manual(config: RigConfig) -> AmplifierRole:
    from hopkinson.drivers.manual_conditioner import ManualConditioner

    amp = config.amplifier
    return ManualConditioner(gain=amp.gain, excitation_v=amp.excitation_v, lowpass_hz=amp.lowpass_hz,
                             sensitivity_v_per_m_s2=amp.sensitivity_v_per_m_s2 or None, identity=amp.identity)


def _scpi_digitizer(config: RigConfig) -> DigitizerRole:
    from hopkinson.drivers.digitizer import Digitizer

    return Digitizer(**config.digitizer.driver_options())  # type: ignore[return-value]


BUILT_IN: dict[str, dict[str, Callable[[RigConfig], Any]]] = {
    "valve_controller": {"modbus": _modbus_controller},
    "digitizer": {"scpi": _scpi_digitizer},
    "amplifier": {"serial-bridge": _serial_bridge, "manual": _manual},
}
DEFAULT_DRIVER = {"valve_controller": "modbus", "digitizer": "scpi", "amplifier": "serial-bridge"}


def make_instrument(config: RigConfig, role: str) -> Any:
    """The driver of one role ("valve_controller", "digitizer", "amplifier"), not connected.

    ConfigError for a driver that cannot be built or does not play its role;
    InstrumentConnectionError when a "sim:" port names a simulator that is not running."""
    section = getattr(config, role)
    driver = getattr(section, "driver", DEFAULT_DRIVER[role])
    if driver in BUILT_IN[role]:
        return BUILT_IN[role][driver](config)
    where = f"{config.path or 'rig config'}: {role}.driver"
    cls = driver_class(driver, role, where)
    options = dict(getattr(section, "options", {}) or {})
    try:
        instrument = cls(**options)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{config.path or 'rig config'}: {role}.options: {driver} does not accept them: "
                          f"{exc}") from None
    missing = missing_members(instrument, ROLES[role])
    if missing:
        raise ConfigError(f"{where}: {driver} cannot be the {role.replace('_', ' ')}: it has no "
                          f"{', '.join(missing)} (see docs/writing-a-driver.md)")
    return instrument


def make_instruments(config: RigConfig) -> Instruments:
    """The three drivers configured from `config`, not yet connected."""
    return Instruments(
        valves=make_instrument(config, "valve_controller"),
        digitizer=make_instrument(config, "digitizer"),
        amplifier=make_instrument(config, "amplifier"),
    )


@contextlib.contextmanager
def open_instruments(config: RigConfig,
                     simulated_truth: Callable[[], dict[str, Any] | None] | None = None) -> Iterator[Instruments]:
    """Connect all three instruments of `config`; close them all on exit (module docstring)."""
    instruments = make_instruments(config)
    instruments.simulated_truth = simulated_truth
    try:
        instruments.valves.connect()
        instruments.digitizer.connect()
        instruments.amplifier.connect()
        yield instruments
    finally:
        instruments.close()


def resolve_port(port: str, instrument: str) -> str:
    """A "sim:..." port as this user's running `hopkinson sim` has it; any other port as is."""
    if not port.startswith(SIM_PORT_PREFIX):
        return port
    from hopkinson.drivers.sim.simulated_rig import ADDRESSES_FILE, read_running_addresses

    key = SIM_PORTS.get(port)
    if key is None:
        raise ConfigError(f"{instrument}: port {port!r}: the simulator has {', '.join(SIM_PORTS)}")
    addresses = read_running_addresses()
    if addresses is None:
        raise InstrumentConnectionError(instrument, "open", f"port {port!r} names the simulated rig, but no "
                                        f"`hopkinson sim` is running for this user (no live {ADDRESSES_FILE})")
    found = addresses.get(key) or ""
    if not found:
        raise InstrumentConnectionError(instrument, "open", f"the running `hopkinson sim` has no {port!r} "
                                        "(is its controller on Modbus TCP?)")
    return str(found)


def sim_rig_config(base: RigConfig, rig: SimulatedRig) -> RigConfig:
    """`base` with the drivers, addresses and register map of a running simulated rig."""
    a = rig.addresses
    vc: ValveControllerConfig = dataclasses.replace(
        base.valve_controller, driver="modbus", options={}, transport=a.modbus_transport,
        host=a.modbus_host, port=a.modbus_port or base.valve_controller.port,
        serial_port=a.modbus_serial_port, baudrate=a.modbus_baudrate, parity=a.modbus_parity,
        stopbits=a.modbus_stopbits, unit_id=a.modbus_unit_id,
        **register_tables(register_map_of(rig.config.register_map)), **sim_fire_style(rig))
    amp: AmplifierConfig = base.amplifier
    if amp.driver != "manual":  # a manual conditioner stays as entered; anything else: the simulated one
        amp = dataclasses.replace(amp, driver="serial-bridge", options={}, port=a.serial_port,
                                  baudrate=a.amplifier_baudrate)
    return dataclasses.replace(
        base,
        valve_controller=vc,
        digitizer=sim_digitizer_config(base.digitizer, a.visa_resource, a.digitizer_dialect, a.digitizer_channels),
        amplifier=amp,
    )


def sim_fire_style(rig: SimulatedRig) -> dict[str, Any]:
    """How the simulated controller fires, as [valve_controller] keys (docs/plc-fire-styles.md)."""
    s = rig.config.servers
    return {"fire_style": s.modbus_fire_style, "fire_command_value": s.modbus_fire_command_value,
            "host_timed_fire_allowed": s.modbus_fire_style == "host_timed_coil"}


def sim_digitizer_config(base: DigitizerConfig, resource: str, dialect: str,
                         channels: dict[str, int]) -> DigitizerConfig:
    """`base` with the simulated digitizer's resource, dialect and channels: each role of
    `channels` (role -> channel number) named as the dialect names it; a role of `base` on
    another channel kept (renamed for the dialect), one on a simulator's channel dropped, and a
    quadrature or second-sensor role the simulated world does not make dropped (the shipped
    rig-sim.toml maps the quadrature photodetector; a world with one photodetector leaves that
    channel flat, and its analysis would fail on it); a
    quadrature or second-sensor channel without a range takes the doppler's or response's; the
    sample format kept where the dialect can send it (else int16, which every dialect can);
    the driver the project's SCPI one."""
    from hopkinson.drivers.scpi_dialect import resolve_dialect

    cls = resolve_dialect(dialect)
    spelled = {role: cls.channel_names[number - 1] for role, number in channels.items()}
    for role, name in base.channels.items():
        if role in PARTNERS and role not in spelled:
            continue  # the simulated world makes no such signal: its channel would be flat
        try:
            renamed = cls().channel_name(name)
        except ValueError:  # a lab's own naming: not a channel of the simulator
            continue
        if role not in spelled and renamed not in spelled.values():
            spelled[role] = renamed
    fmt = base.sample_format if base.sample_format in cls.sample_formats else "int16"
    ranges = {role: v for role, v in base.ranges_v.items() if role in spelled}
    for role, like in PARTNERS.items():
        if role in spelled and role not in ranges:  # a partner channel takes its first's range
            ranges[role] = ranges.get(like, base.ch1_range_v if like == "doppler" else base.ch2_range_v)
    return dataclasses.replace(base, driver="scpi", options={}, resource=resource, dialect=dialect,
                               channels=spelled, sample_format=fmt, ranges_v=ranges)


def with_sim_channels(base: RigConfig, sim: SimConfig) -> RigConfig:
    """`base` with the digitizer channels a simulated rig of `sim` will give it (what
    sim_rig_config sets once it runs): to check a request or a plan against before it starts."""
    digitizer = sim_digitizer_config(base.digitizer, base.digitizer.resource, sim.servers.digitizer_dialect,
                                     sim.world.channels())
    return dataclasses.replace(base, digitizer=digitizer)


def sim_digitizer_lines(dialect: str, channels: dict[str, int]) -> list[str]:
    """What a rig config needs to reach a simulated digitizer of this dialect (printed by
    `hopkinson sim`)."""
    from hopkinson.drivers.scpi_dialect import resolve_dialect

    cls = resolve_dialect(dialect)
    named = ", ".join(f'{role} = "{cls.channel_names[n - 1]}"' for role, n in channels.items())
    lines = [f'rig config: [digitizer] dialect = "{dialect}"; [digitizer.channels] {named}']
    partners = [role for role in PARTNERS if role in channels]
    if partners:  # channels beyond 1 and 2 need their range (the simulator's: 1 V and 10 V)
        ranges = ", ".join(f"{role} = {1.0 if role == 'doppler_quadrature' else 10.0}" for role in partners)
        lines.append(f"            [digitizer.ranges_v] {ranges}")
    return lines
