"""Rig configuration (config/rig.toml) and simulator configuration (config/sim.toml).

`load_rig_config(path) -> RigConfig` reads the TOML file and returns typed, frozen dataclasses,
one per section; `load_sim_config(path) -> SimConfig` does the same for the simulator's file.
docs/configuration.md describes every section for a lab writing its rig.toml.

Each key is declared once, as a field of its section with its type, default, bounds and
description (drivers/config_fields.py tells how); pydantic validates a file against these
declarations (rig/config_errors.py turns its first error into one line naming the file, the
key and the reason), and `hopkinson config schema` writes the same declarations as JSON Schema
for an editor. The register map's tables are the driver's (drivers/registers.py), the
amplifier's steps its driver's declared settings (drivers/amplifier.py `SETTINGS`), the
simulator's tables drivers/sim/world_params.py and drivers/sim/real_records.py. The lab's and
the bar's sections are in rig/config_lab.py. Then the file is checked as a whole
(rig/config_checks.py): thresholds against the pressure limits, the gauge's resolution and
what each register can hold, the register map for overlaps and the registers the safety
functions need, each driver's own keys.

A serial port may be written ``"sim:amplifier"`` or ``"sim:controller"``: the port of this
user's running `hopkinson sim`, looked up when the instruments are opened (rig/instruments.py),
never a fixed path in the shared /tmp.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, Field, ValidationInfo
from pydantic.json_schema import SkipJsonSchema

from hopkinson.drivers import config_fields as fields
from hopkinson.drivers import registers
from hopkinson.drivers.amplifier import EXCITATION
from hopkinson.drivers.amplifier import SETTINGS as BRIDGE_SETTINGS
from hopkinson.drivers.config_fields import SECTION, Hint, Int, Number, Text
from hopkinson.drivers.digitizer_settings import DigitizerSettings
from hopkinson.drivers.fire_styles import FIRE_STYLE_DOC, FIRE_STYLES
from hopkinson.drivers.modbus_link import ModbusTarget
from hopkinson.rig.config_analysis import options_section
from hopkinson.rig.config_checks import check_limits_stated, check_register_map, check_rig
from hopkinson.rig.config_errors import validate
from hopkinson.rig.config_lab import (
    BAR_MATERIALS,
    BAR_MOUNTS,
    BarConfig,
    BarProjectileConfig,
    BarSegmentConfig,
    DatabaseConfig,
    LabConfig,
    ReferenceCertificateConfig,
    SignatoryConfig,
)
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.toml_file import read_toml

if typing.TYPE_CHECKING:
    from hopkinson.drivers.sim.simulated_rig import SimConfig

__all__ = ["BAR_MATERIALS", "BAR_MOUNTS", "AmplifierConfig", "AnalysisConfig", "BarConfig", "BarProjectileConfig",
           "BarSegmentConfig", "DatabaseConfig", "DigitizerConfig", "LabConfig", "LimitsConfig",
           "PlausibilityConfig", "ReferenceCertificateConfig", "RigConfig", "SignatoryConfig", "TimeoutsConfig", "UncertaintyConfig", "ValveControllerConfig",
           "controller_map_of", "load_rig_config", "load_sim_config", "register_map_of", "register_tables"]

FireStyleName = typing.Literal[FIRE_STYLES]  # type: ignore[valid-type]  # drivers/fire_styles.py
Seconds = Annotated[Number, Field(gt=0, le=3600)]
Retries = Annotated[Int, Field(ge=0, le=10, description="re-sends after a timeout or a garbled reply")]
Port = Annotated[Int, Field(ge=1, le=65535)]


@dataclass(frozen=True)
class ValveControllerConfig:
    """[valve_controller]: the gas/vacuum controller: its driver, Modbus link and register map.

    driver "modbus" (the project's, drivers/valve_controller.py) or a lab's own class
    ("package.module:Class" or an entry point of the `hopkinson.drivers` group), which gets
    the [valve_controller.options] table as keyword arguments. The register map's four tables
    ([valve_controller.coils] …) are drivers/registers.py's.
    """

    __pydantic_config__ = SECTION
    driver: Annotated[Text, Field(description='"modbus", or a lab\'s own class "package.module:Class"')] = "modbus"
    options: Annotated[dict[str, Any], Field(description="a lab's own driver: keyword arguments of its class")] = (
        field(default_factory=dict))
    transport: Annotated[fields.Transport, Field(description="tcp: host and port; rtu: serial_port, baudrate, parity, "
                                                      "stopbits")] = "tcp"
    host: Annotated[Text, Field(description="the controller's address on Modbus TCP")] = ""
    port: Annotated[Port, Field(description="the controller's TCP port")] = 502
    serial_port: Annotated[Text, Field(description="RTU: the RS-485 port, or \"sim:controller\"")] = ""
    baudrate: fields.Baud = 19200
    parity: fields.Parity = "N"
    stopbits: fields.StopBits = 1
    unit_id: Annotated[Int, Field(ge=1, le=247, description="Modbus unit (slave) id")] = 1
    timeout_s: Annotated[Seconds, Field(description="per request")] = 1.0
    retries: Retries = 0
    watchdog_s: Annotated[Number, Field(ge=0.2, le=60, description="the controller's link watchdog: it vents when "
                                                                   "the heartbeat is silent this long"),
                          Hint("the controller's link watchdog, seconds")] = 3.0
    fire_pulse_s: Annotated[Number, Field(gt=0, le=10, description="fire-valve pulse, timed by the "
                                                                   "controller")] = 0.2
    # How the PLC fires (drivers/fire_styles.py, docs/plc-fire-styles.md); what each style needs
    # is checked by rig/config_checks.py check_fire_style.
    fire_style: Annotated[FireStyleName, Field(description="how the PLC fires (docs/plc-fire-styles.md)"),
                          Hint(FIRE_STYLE_DOC)] = "pulse_register"
    fire_command_value: Annotated[Int, Field(ge=1, le=65535, description=(
        "preset_and_command: the word written to holding_registers.fire_command to fire"))] = 1
    host_timed_fire_allowed: Annotated[fields.Flag, Field(description=(
        "host_timed_coil: the lab accepts a pulse timed by this computer (the watchdog closes the valve if "
        "it stops)"))] = False
    # The register map (drivers/registers.py): where each signal lives on the controller.
    coils: Annotated[registers.CoilMap, Field(description="the actuators: True = open / running")] = field(
        default_factory=registers.CoilMap)
    discrete_inputs: Annotated[registers.DiscreteInputMap, Field(description=(
        "interlocks (True = safe) and valve limit switches (True = open)"))] = field(
        default_factory=registers.DiscreteInputMap)
    holding_registers: Annotated[registers.HoldingRegisterMap, Field(description="what the host writes")] = field(
        default_factory=registers.HoldingRegisterMap)
    input_registers: Annotated[registers.InputRegisterMap, Field(description="what the host reads")] = field(
        default_factory=registers.InputRegisterMap)

    @property
    def register_map(self) -> registers.RegisterMap:
        """The four tables as the driver takes them."""
        return registers.RegisterMap(self.coils, self.discrete_inputs, self.holding_registers, self.input_registers)

    @property
    def target(self) -> ModbusTarget:
        """Where the controller is, as the Modbus driver takes it."""
        return ModbusTarget(self.transport, host=self.host, port=self.port, serial_port=self.serial_port,
                            baudrate=self.baudrate, parity=self.parity, stopbits=self.stopbits,
                            unit_id=self.unit_id)

    @property
    def address(self) -> str:
        """The rig's identity for its lock, e.g. "modbus-tcp://127.0.0.1:5020/1"."""
        if self.driver != "modbus":  # a lab's driver: its class and where its options point
            return f"{self.driver}?" + "&".join(f"{k}={v}" for k, v in sorted(self.options.items()))
        return self.target.address

    @property
    def gauge_resolution_bar(self) -> float:
        """One count of the reservoir gauge, bar (0 for a float32 gauge)."""
        return self.input_registers.reservoir_pressure.resolution


def register_tables(register_map: registers.RegisterMap) -> dict[str, Any]:
    """A driver's map as ValveControllerConfig's four table fields (for dataclasses.replace)."""
    return {f.name: getattr(register_map, f.name) for f in dataclasses.fields(register_map)}


DIGITIZER_ROLES = ("doppler", "response", "doppler_quadrature", "response_2")


@dataclass(frozen=True)
class DigitizerConfig:
    """[digitizer]: the digitizer's VISA link, dialect, channels by role and acquisition settings.

    dialect: the instrument's command set, "generic" | "keysight" | "tektronix" | "lecroy", or a
    lab's own "package.module:Class" (a drivers.scpi_dialect.DigitizerDialect). channels: role ->
    the instrument's channel name, doppler and response required. ranges_v: role -> full scale
    (the channel reads ±range); a role without one takes ch1_range_v / ch2_range_v when it is
    on the dialect's channel 1 / 2 (the older keys). trigger_source: a role, a channel or the
    external input ("EXT"). driver "scpi" (drivers/digitizer.py) or a lab's own class with
    [digitizer.options]; channel names are then taken as written.
    """

    __pydantic_config__ = SECTION
    resource: Annotated[Text, Field(description="VISA resource, e.g. TCPIP0::192.168.10.21::5025::SOCKET")] = ""
    driver: Annotated[Text, Field(description='"scpi", or a lab\'s own class "package.module:Class"')] = "scpi"
    options: Annotated[dict[str, Any], Field(description="a lab's own driver: keyword arguments of its class")] = (
        field(default_factory=dict))
    dialect: Annotated[Text, Field(description='generic | keysight | tektronix | lecroy | '
                                               '"package.module:Class"')] = "generic"
    visa_library: Annotated[Text, Field(description='"@py" (pyvisa-py), a system VISA\'s library path, or '
                                                    '"@ivi"')] = "@py"
    read_termination: Text = "\n"
    write_termination: Text = "\n"
    max_reply_bytes: Annotated[Int, Field(ge=64, le=1 << 24)] = 65536
    sample_format: Annotated[typing.Literal["int8", "uint8", "int16", "uint16", "float32"], Field(
        description="as the dialect can send")] = "int16"
    byte_order: typing.Literal["little", "big"] = "little"
    timeout_s: Seconds = 5.0
    sample_rate_hz: Annotated[Number, Field(ge=1e3, le=1e10)] = 100e6
    record_length: Annotated[Int, Field(ge=16, le=100_000_000)] = 200_000
    pre_trigger_fraction: Annotated[Number, Field(ge=0, le=0.95)] = 0.1
    channels: Annotated[dict[str, Text], Field(description="role -> the digitizer's channel (doppler, response, "
                                                           "doppler_quadrature, response_2)")] = field(
        default_factory=lambda: {"doppler": "CH1", "response": "CH2"})
    ranges_v: Annotated[dict[str, Any], Field(description="role -> full scale: the channel reads -range .. "
                                                          "+range volts")] = field(default_factory=dict)
    ch1_range_v: Annotated[Number, Field(gt=0, le=100)] = 1.0
    ch2_range_v: Annotated[Number, Field(gt=0, le=100)] = 10.0
    trigger_source: Annotated[Text, Field(description="a channel (CH1 .. CH4), EXT, or a role")] = "CH2"
    trigger_level_v: Number = 0.2
    trigger_slope: typing.Literal["POS", "NEG"] = "POS"

    def __post_init__(self) -> None:
        """Check the keys that depend on each other; ValueError names the key (the loader
        prefixes file and section)."""
        from hopkinson.drivers.digitizer_waveform import BYTE_ORDERS, SAMPLE_FORMATS
        from hopkinson.drivers.scpi_dialect import resolve_dialect

        scpi = self.driver == "scpi"
        if scpi and not self.resource:
            raise ValueError("resource: missing key (the digitizer's VISA resource)")
        if scpi and self.options:
            raise ValueError("options: only for a lab's own driver (driver = \"package.module:Class\")")
        try:
            dialect = resolve_dialect(self.dialect)
        except ValueError as exc:
            raise ValueError(f"dialect: {exc}") from None
        if self.sample_format not in SAMPLE_FORMATS or (scpi and self.sample_format not in dialect.sample_formats):
            known = dialect.sample_formats if scpi else SAMPLE_FORMATS
            raise ValueError(f"sample_format: must be one of {', '.join(known)} for the {dialect.name} dialect, "
                             f"got {self.sample_format!r}")
        if self.byte_order not in BYTE_ORDERS:
            raise ValueError(f"byte_order: must be little or big, got {self.byte_order!r}")
        for key in ("read_termination", "write_termination"):
            value = getattr(self, key)
            if not (value and value.isascii() and len(value) <= 2):
                raise ValueError(f"{key}: must be one or two ASCII characters (e.g. \"\\n\"), got {value!r}")
        for role in self.channels:
            if role not in DIGITIZER_ROLES:
                raise ValueError(f"channels.{role}: not a role (roles: {', '.join(DIGITIZER_ROLES)})")
        for role in self.ranges_v:
            if role not in self.channels:
                raise ValueError(f"ranges_v.{role}: no such role in [digitizer.channels] ({', '.join(self.channels)})")
        for role in ("doppler", "response"):
            if role not in self.channels:
                raise ValueError(f"channels.{role}: missing key (the {role} channel's name)")
        named = {}
        for role, channel in self.channels.items():
            try:
                named[role] = dialect().channel_name(channel) if scpi else str(channel)
            except ValueError as exc:
                raise ValueError(f"channels.{role}: {exc}") from None
        if len(set(named.values())) != len(named):
            raise ValueError(f"channels: two roles on one channel ({named})")
        object.__setattr__(self, "channels", named)
        for role in named:
            range_v = self.range_v(role)
            if isinstance(range_v, bool) or not isinstance(range_v, int | float) or not 0 < range_v <= 100:
                raise ValueError(f"ranges_v.{role}: must be above 0 and at most 100 V, got {range_v!r}")
        self.trigger_channel  # noqa: B018  (checks trigger_source)

    def range_v(self, role: str) -> float:
        """Full scale (±V) of a role's channel."""
        if role in self.ranges_v:
            return self.ranges_v[role]
        number = "".join(c for c in self.channels[role] if c.isdigit())
        if number in ("1", "2"):
            return self.ch1_range_v if number == "1" else self.ch2_range_v
        raise ValueError(f"ranges_v.{role}: missing key (the range of {self.channels[role]})")

    @property
    def trigger_channel(self) -> str:
        """The trigger source as the instrument names it (a role resolved to its channel)."""
        from hopkinson.drivers.scpi_dialect import resolve_dialect

        source = self.channels.get(self.trigger_source, self.trigger_source)
        if self.driver != "scpi":
            return source
        try:
            return resolve_dialect(self.dialect)().trigger_source_name(source)
        except ValueError as exc:
            raise ValueError(f"trigger_source: {exc}; or a role ({', '.join(self.channels)})") from None

    @property
    def pre_trigger_samples(self) -> int:
        return min(int(round(self.pre_trigger_fraction * self.record_length)), self.record_length - 1)

    def settings(self) -> DigitizerSettings:
        """The acquisition settings this configuration asks for (ARM compares the read-back)."""
        return DigitizerSettings(
            sample_rate_hz=self.sample_rate_hz, record_length=self.record_length,
            pre_trigger_samples=self.pre_trigger_samples,
            ranges_v={channel: float(self.range_v(role)) for role, channel in self.channels.items()},
            trigger_source=self.trigger_channel, trigger_level_v=self.trigger_level_v,
            trigger_slope=self.trigger_slope)

    def driver_options(self) -> dict[str, Any]:
        """Keyword arguments of drivers.digitizer.Digitizer for this configuration."""
        return {"resource": self.resource, "timeout_s": self.timeout_s, "dialect": self.dialect,
                "channels": dict(self.channels), "visa_library": self.visa_library,
                "read_termination": self.read_termination, "write_termination": self.write_termination,
                "max_reply_bytes": self.max_reply_bytes, "sample_format": self.sample_format,
                "byte_order": self.byte_order}


def _bridge_step(value: float, info: ValidationInfo) -> float:
    """The serial bridge amplifier's own settings (drivers/amplifier.py SETTINGS) for its driver."""
    if info.data.get("driver") == "serial-bridge":
        control = next(c for c in BRIDGE_SETTINGS if c.name == info.field_name)
        if not control.allows(value):
            raise ValueError(f"the serial bridge amplifier has {control.allowed_text()}; got {value:g}")
    return value


BridgeSetting = AfterValidator(_bridge_step)


@dataclass(frozen=True)
class AmplifierConfig:
    """[amplifier]: the sensor's conditioner.

    driver "serial-bridge" (drivers/amplifier.py: port, baudrate, ...; gain, excitation and
    low-pass are set and read back, and must be among its declared settings), "manual"
    (drivers/manual_conditioner.py: no I/O; gain, excitation, low-pass, sensitivity and identity
    are what the technician entered), or a lab's own class with [amplifier.options].
    """

    __pydantic_config__ = SECTION
    driver: Annotated[Text, Field(description='"serial-bridge" | "manual" | "package.module:Class"')] = (
        "serial-bridge")
    options: Annotated[dict[str, Any], Field(description="a lab's own driver: keyword arguments of its class")] = (
        field(default_factory=dict))
    port: Annotated[Text, Field(description='serial-bridge: its serial port, or "sim:amplifier"')] = ""
    baudrate: fields.Baud = 115200
    timeout_s: Seconds = 1.0
    retries: Retries = 1
    gain: Annotated[Number, Field(gt=0, le=1e6, description="output volts per input volt"), BridgeSetting] = 10.0
    excitation_v: Annotated[Number, Field(ge=0, le=EXCITATION.limits[1] if EXCITATION.limits else 10.0,
                                          description="bridge excitation (0: none)"), BridgeSetting] = 5.0
    lowpass_hz: Annotated[Number, Field(ge=0, le=1e8, description="the filter corner; 0 = off"),
                          Hint("0 (off) or the filter corner"), BridgeSetting] = 200_000.0
    sensitivity_v_per_m_s2: Annotated[Number, Field(ge=0, le=1, description=(
        "manual: the sensitivity entered on the conditioner (0: not entered)")),
        Hint("0 (not entered) or the sensitivity")] = 0.0
    identity: Annotated[Text, Field(description="manual: make, model, serial as the technician reads them")] = ""


@dataclass(frozen=True)
class LimitsConfig:
    """[limits]: what the sequencer accepts before it fires (gauge bar, absolute mbar). A rig's
    file states every one of them (never a default)."""

    __pydantic_config__ = SECTION
    max_pressure_bar: Annotated[Number, Field(gt=0, le=100, description="never charge above this (gauge)")] = 8.0
    min_pressure_bar: Annotated[Number, Field(ge=0, le=100, description="a shot below this is refused")] = 0.2
    pressure_tolerance_bar: Annotated[Number, Field(gt=0, le=10, description="charged when within this of the "
                                                                            "set-point")] = 0.05
    fixture_vacuum_max_mbar: Annotated[Number, Field(gt=0, le=1100, description=(
        "fire only with the fixture below this (absolute)"))] = 100.0
    vent_done_bar: Annotated[Number, Field(gt=0, le=10, description="SAFE: the reservoir counts as vented below "
                                                                    "this")] = 0.05


@dataclass(frozen=True)
class PlausibilityConfig:
    """[plausibility]: what the controller's readings can be at all (rig/plausibility.py,
    docs/plausibility.md); a reading outside fails `probe` and CHECK as a register-map mistake
    (word order, scale, type), never as a pressure to vent. Checked against [limits] by
    rig/config_checks.py check_plausibility."""

    __pydantic_config__ = SECTION
    reservoir_min_bar: Annotated[Number, Field(ge=-1.1, le=0, description=(
        "the lowest reading of the reservoir gauge (gauge bar; a gauge cannot read below -1.013 bar)")),
        Hint("a gauge cannot read below -1.013 bar")] = -1.0
    reservoir_max_bar: Annotated[Number, Field(ge=0, le=1000, description=(
        "the reservoir gauge's full scale, gauge bar (0: twice limits.max_pressure_bar)")),
        Hint("0: twice limits.max_pressure_bar")] = 0.0
    vacuum_max_mbar: Annotated[Number, Field(ge=1013.25, le=2000, description=(
        "the highest absolute fixture pressure (ambient is ~1013 mbar)")), Hint("at least ambient, 1013.25 mbar")] = (
        1100.0)
    pulse_count_max: Annotated[Int, Field(ge=1, le=2**32 - 1, description=(
        "the most fire pulses a controller can have counted (a fire valve lives ~10 million cycles)"))] = 10_000_000

    def reservoir_range_bar(self, limits: LimitsConfig) -> tuple[float, float]:
        """(lowest, highest) plausible reservoir gauge reading, bar."""
        high = self.reservoir_max_bar if self.reservoir_max_bar > 0 else 2.0 * limits.max_pressure_bar
        return self.reservoir_min_bar, high


@dataclass(frozen=True)
class TimeoutsConfig:
    """[timeouts]: longest time each sequencer state may take, seconds."""

    __pydantic_config__ = SECTION
    check_s: Annotated[Seconds, Field(description="CHECK: instruments answer, interlocks hold")] = 5.0
    evacuate_s: Annotated[Seconds, Field(description="EVACUATE: the fixture pumped below its limit")] = 60.0
    charge_s: Annotated[Seconds, Field(description="CHARGE: the reservoir filled to the set-point")] = 120.0
    arm_s: Annotated[Seconds, Field(description="ARM: the digitizer armed, settings read back")] = 5.0
    fire_s: Annotated[Seconds, Field(description="FIRE: the pulse fired and counted")] = 5.0
    capture_s: Annotated[Seconds, Field(description="CAPTURE: the record transferred")] = 10.0
    safe_s: Annotated[Seconds, Field(description="SAFE: valves closed and read back, reservoir vented")] = 60.0
    store_s: Annotated[Seconds, Field(description="STORE: the shot file written")] = 30.0
    analyse_s: Annotated[Seconds, Field(description="ANALYSE: the shot analysed")] = 120.0


# [analysis] and [uncertainty]: analysis options, each declared once in analysis/options.py
# (type, default, unit, bounds, description); rig/config_analysis.py makes the sections.
AnalysisConfig = options_section(
    "AnalysisConfig", __name__, "[analysis]: interferometer and sensor constants, the analysis rate and the "
    "automatic DCM's limits (analysis.options); amp_gain_2 and sensitivity_2_v_per_m_s2: a second sensor "
    "(digitizer role response_2), through its own conditioner set by hand (both 1: its results in volts); "
    "transverse_sensitivity_2_rel and asymmetry_bound_2_rel: what its data sheet states (unset: [uncertainty]'s).",
    ("grating_pitch_m", "orders", "sensitivity_v_per_m_s2", "sample_rate_hz", "dcm_widening", "dcm_noise_gain_limit"),
    unset=("transverse_sensitivity_2_rel", "asymmetry_bound_2_rel"),
    apart={"amp_gain_2": "amp_gain", "sensitivity_2_v_per_m_s2": "sensitivity_v_per_m_s2",
           "transverse_sensitivity_2_rel": "transverse_sensitivity_rel", "asymmetry_bound_2_rel": "asymmetry_bound_rel"})
UncertaintyConfig = options_section(
    "UncertaintyConfig", __name__, "[uncertainty]: the reference chain's relative standard uncertainties (k = 1, "
    "from the lab's calibration certificates; the defaults are typical values), the channel skew, the bar's "
    "transverse motion, the sensors' stated transverse sensitivity and asymmetry bound where a plan or the panel "
    "does not state a sensor's own, and the Monte Carlo draws per shot (analysis.uncertainty).",
    {"grating_pitch_rel": "u_grating_pitch_rel", "interferometer_rel": "u_interferometer_rel",
     "amplifier_gain_rel": "u_amp_gain_rel", "digitizer_gain_rel": "u_digitizer_gain_rel",
     "channel_skew_s": "u_channel_skew_s", "draws": "draws", "transverse_motion_rel": "transverse_motion_rel",
     "transverse_sensitivity_rel": "transverse_sensitivity_rel", "asymmetry_bound_rel": "asymmetry_bound_rel"})


@dataclass(frozen=True)
class RigConfig:
    """The whole of config/rig.toml, validated."""

    __pydantic_config__ = SECTION
    valve_controller: ValveControllerConfig
    digitizer: DigitizerConfig
    amplifier: AmplifierConfig
    limits: LimitsConfig = field(default_factory=LimitsConfig)
    plausibility: PlausibilityConfig = field(default_factory=PlausibilityConfig)
    timeouts: TimeoutsConfig = field(default_factory=TimeoutsConfig)
    analysis: AnalysisConfig = field(default_factory=AnalysisConfig)
    uncertainty: UncertaintyConfig = field(default_factory=UncertaintyConfig)
    lab: LabConfig = field(default_factory=LabConfig)
    bar: BarConfig = field(default_factory=BarConfig)
    database: DatabaseConfig = field(default_factory=DatabaseConfig)
    path: SkipJsonSchema[str] = ""  # where it was loaded from (not a TOML key)

    def snapshot(self) -> dict[str, Any]:
        """The configuration as a JSON-ready dict (for shot files), shaped like the TOML file."""
        data = _jsonable(dataclasses.asdict(self))
        del data["database"]  # the URL may hold a password: never in a shot file
        return data


# -- public loaders ---------------------------------------------------------------------------
def load_rig_config(path: str | Path) -> RigConfig:
    """Read and validate config/rig.toml (or a variant); ConfigError on anything wrong."""
    path = Path(path)
    data, _ = read_toml(path)
    if "path" in data:
        raise ConfigError(f"{path}: path: unknown section in top level (it is where the file was read from)")
    config = validate(RigConfig, data, path)
    check_rig(config, path)
    check_limits_stated(data, path)
    return dataclasses.replace(config, path=str(path))


def load_sim_config(path: str | Path) -> SimConfig:
    """Read and validate config/sim.toml; ConfigError on anything wrong."""
    # Imported here: the simulator's servers are only loaded by the commands that run them.
    from hopkinson.drivers.sim.simulated_rig import SimConfig
    from hopkinson.rig.config_sim import SimFile

    path = Path(path)
    data, _ = read_toml(path)
    sim = validate(SimFile, data, path)
    check_register_map(sim.register_map, path, "register_map")
    return SimConfig(world=sim.world, servers=sim.servers, register_map=controller_map_of(sim.register_map))


def controller_map_of(register_map: registers.RegisterMap) -> dict[str, dict[str, Any]]:
    """The simulated controller's map (drivers/sim/controller_map.py) for a driver's map."""
    from hopkinson.drivers.sim.controller_map import Point

    return {table: {name: Point(**dataclasses.asdict(entry)) if isinstance(entry, registers.Register)
                    else Point(entry) for name, entry in entries.items()}
            for table, entries in register_map.blocks().items()}


def register_map_of(controller_map: dict[str, dict[str, Any]]) -> registers.RegisterMap:
    """The driver's map that reaches a simulated controller laid out by `controller_map`."""
    tables = {}
    for block in dataclasses.fields(registers.RegisterMap):
        table_type = typing.get_type_hints(registers.RegisterMap)[block.name]
        points = controller_map.get(block.name, {})
        values: dict[str, Any] = {}
        for f in dataclasses.fields(table_type):
            point = points.get(f.name)
            if typing.get_type_hints(table_type)[f.name] is registers.Register:
                values[f.name] = registers.Register(**dataclasses.asdict(point)) if point else registers.Register()
            else:
                values[f.name] = point.address if point is not None else -1
        tables[block.name] = table_type(**values)
    return registers.RegisterMap(**tables)


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    return obj
