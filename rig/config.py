"""Rig configuration (config/rig.toml) and simulator configuration (config/sim.toml).

`load_rig_config(path) -> RigConfig` reads the TOML file and returns typed, frozen dataclasses,
one per section:

    [valve_controller]   driver, transport (tcp | rtu), host, port, serial_port, baudrate, parity,
                         stopbits, unit_id, timeout_s, retries, watchdog_s, fire_pulse_s
      [valve_controller.coils | .discrete_inputs | .holding_registers | .input_registers]
      [valve_controller.options]  (a lab's own driver: keyword arguments of its class)
    [digitizer]          resource, dialect (generic | keysight | tektronix | lecroy | package.module:Class),
                         visa_library, read_termination, write_termination, max_reply_bytes,
                         sample_format, byte_order, timeout_s, sample_rate_hz, record_length,
                         pre_trigger_fraction, trigger_source, trigger_level_v, trigger_slope
      [digitizer.channels]  role -> channel: doppler, response, doppler_quadrature, response_2
      [digitizer.ranges_v]  role -> full scale (±V); older form: ch1_range_v, ch2_range_v
    [amplifier]          driver (serial-bridge | manual | ...), port, baudrate, timeout_s, retries,
                         gain, excitation_v, lowpass_hz, sensitivity_v_per_m_s2, identity
    [limits]             max_pressure_bar, min_pressure_bar, fixture_vacuum_max_mbar, ...
    [timeouts]           check_s, evacuate_s, charge_s, arm_s, fire_s, capture_s, safe_s, store_s, analyse_s
    [analysis]           grating_pitch_m, orders, sensitivity_v_per_m_s2, sample_rate_hz,
                         dcm_widening, dcm_noise_gain_limit, amp_gain_2, sensitivity_2_v_per_m_s2
    [lab]                name, address, accreditation, certificate_prefix, rig, decision_rule
      [[lab.reference_chain]]  item, certificate, issued_by, u_rel, due ("YYYY-MM-DD"), budget
      [[lab.signatories]]      name, role (who may authorise a certificate); [lab] country (for the DCC)
    [database]           url (sqlite:///FILE or postgresql://…; default SQLite in the data folder)

`load_sim_config(path) -> SimConfig` does the same for the simulator's file ([servers],
[world] with its sub-tables, [register_map]).

Validation happens at load: an unknown section or key, a wrong type or a value out of range
raises ConfigError naming the file, the key (dotted, e.g. "valve_controller.coils.fire_valve")
and the reason. The rules are the RULES table below (one line per key pattern), applied by
one generic reader of dataclasses (`_build`), so every section is checked the same way. Then
the file is checked as a whole (`_check_rig`): thresholds against the pressure limits and the
gauge's resolution, every limit against what its register can hold, the register map for
overlaps and the registers the safety functions need, each driver's own keys.

Register values are written either as an address (a uint16, scale 1) or as a table
``{ address = 0, type = "float32", word_order = "little", scale = 1.0, offset = 0.0 }``
(drivers/registers.py). A serial port may be written ``"sim:amplifier"`` or
``"sim:controller"``: the port of this user's running `hopkinson sim`, looked up when the
instruments are opened (rig/instruments.py), never a fixed path in the shared /tmp.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from dataclasses import dataclass, field
from datetime import date
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from hopkinson.drivers.amplifier import EXCITATION_RANGE_V, GAINS, LOWPASS_HZ
from hopkinson.drivers.digitizer_settings import DigitizerSettings
from hopkinson.drivers.modbus_link import ModbusTarget
from hopkinson.drivers.registers import REGISTER_TYPES, WORD_ORDERS, Register, RegisterMap
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.toml_file import read_toml

if typing.TYPE_CHECKING:
    from hopkinson.drivers.sim.simulated_rig import SimConfig


@dataclass(frozen=True)
class ValveControllerConfig:
    """[valve_controller]: the gas/vacuum controller: its driver, Modbus link and register map.

    driver "modbus" (the project's, drivers/valve_controller.py) or a lab's own class
    ("package.module:Class" or an entry point of the `hopkinson.drivers` group), which gets
    the [valve_controller.options] table as keyword arguments.
    """

    driver: str = "modbus"
    options: dict[str, Any] = field(default_factory=dict)
    transport: str = "tcp"
    host: str = ""
    port: int = 502
    serial_port: str = ""
    baudrate: int = 19200
    parity: str = "N"
    stopbits: int = 1
    unit_id: int = 1
    timeout_s: float = 1.0
    retries: int = 0
    watchdog_s: float = 3.0
    fire_pulse_s: float = 0.2
    register_map: RegisterMap = field(default_factory=RegisterMap, metadata={"inline": True})

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
        return self.register_map.input_registers.reservoir_pressure.resolution


DIGITIZER_ROLES = ("doppler", "response", "doppler_quadrature", "response_2")


@dataclass(frozen=True)
class DigitizerConfig:
    """[digitizer]: the digitizer's VISA link, dialect, channels by role and acquisition settings.

    dialect: the instrument's command set, "generic" | "keysight" | "tektronix" | "lecroy", or a
    lab's own "package.module:Class" (a drivers.scpi_dialect.DigitizerDialect). visa_library:
    "@py" (pyvisa-py), a system VISA's path, or "@ivi". sample_format / byte_order: how the
    samples travel (int8 uint8 int16 uint16 float32; little, big). channels: role -> the
    instrument's channel name, doppler and response required. ranges_v: role -> full scale
    (the channel reads ±range); a role without one takes ch1_range_v / ch2_range_v when it is
    on the dialect's channel 1 / 2 (the older keys). trigger_source: a role, a channel or the
    external input ("EXT"). driver "scpi" (drivers/digitizer.py) or a lab's own class with
    [digitizer.options]; channel names are then taken as written.
    """

    resource: str = ""
    driver: str = "scpi"
    options: dict[str, Any] = field(default_factory=dict)
    dialect: str = "generic"
    visa_library: str = "@py"
    read_termination: str = "\n"
    write_termination: str = "\n"
    max_reply_bytes: int = 65536
    sample_format: str = "int16"
    byte_order: str = "little"
    timeout_s: float = 5.0
    sample_rate_hz: float = 100e6
    record_length: int = 200_000
    pre_trigger_fraction: float = 0.1
    channels: dict[str, str] = field(default_factory=lambda: {"doppler": "CH1", "response": "CH2"})
    ranges_v: dict[str, float] = field(default_factory=dict)
    ch1_range_v: float = 1.0
    ch2_range_v: float = 10.0
    trigger_source: str = "CH2"
    trigger_level_v: float = 0.2
    trigger_slope: str = "POS"

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


@dataclass(frozen=True)
class AmplifierConfig:
    """[amplifier]: the sensor's conditioner.

    driver "serial-bridge" (drivers/amplifier.py: port, baudrate, ...; gain, excitation and
    low-pass are set and read back), "manual" (drivers/manual_conditioner.py: no I/O; gain,
    excitation, low-pass, sensitivity and identity are what the technician entered), or a
    lab's own class with [amplifier.options].
    """

    driver: str = "serial-bridge"
    options: dict[str, Any] = field(default_factory=dict)
    port: str = ""
    baudrate: int = 115200
    timeout_s: float = 1.0
    retries: int = 1
    gain: float = 10.0
    excitation_v: float = 5.0
    lowpass_hz: float = 200_000.0  # 0 = filter off
    sensitivity_v_per_m_s2: float = 0.0  # manual: entered on the conditioner (0 = not entered)
    identity: str = ""  # manual: make, model, serial as the technician reads them


@dataclass(frozen=True)
class LimitsConfig:
    """[limits]: what the sequencer accepts before it fires (gauge bar, absolute mbar)."""

    max_pressure_bar: float = 8.0
    min_pressure_bar: float = 0.2
    pressure_tolerance_bar: float = 0.05
    fixture_vacuum_max_mbar: float = 100.0
    vent_done_bar: float = 0.05


@dataclass(frozen=True)
class TimeoutsConfig:
    """[timeouts]: longest time each sequencer state may take, seconds."""

    check_s: float = 5.0
    evacuate_s: float = 60.0
    charge_s: float = 120.0
    arm_s: float = 5.0
    fire_s: float = 5.0
    capture_s: float = 10.0
    safe_s: float = 60.0
    store_s: float = 30.0
    analyse_s: float = 120.0


@dataclass(frozen=True)
class AnalysisConfig:
    """[analysis]: interferometer and sensor constants and the analysis sample rate."""

    grating_pitch_m: float = 2.0e-6
    orders: tuple[int, int] = (1, -1)
    sensitivity_v_per_m_s2: float = 2.0e-7
    sample_rate_hz: float = 1e6
    dcm_widening: float = 3.0  # automatic DCM: widen the ±5 % band this many times
    dcm_noise_gain_limit: float = 4.0  # DCM white-noise RMS gain allowed at the analysis rate
    # A second sensor (digitizer role response_2): its conditioner's gain (set by hand) and its
    # nominal sensitivity at the conditioner input; both 1 leave its response in volts.
    amp_gain_2: float = 1.0
    sensitivity_2_v_per_m_s2: float = 1.0


@dataclass(frozen=True)
class UncertaintyConfig:
    """[uncertainty]: the reference chain's relative standard uncertainties (k = 1, from the
    lab's calibration certificates; the defaults are typical values, analysis.params) and the
    Monte Carlo draws per shot (analysis.uncertainty)."""

    grating_pitch_rel: float = 1e-4
    interferometer_rel: float = 5e-4
    amplifier_gain_rel: float = 2e-3
    digitizer_gain_rel: float = 2e-3
    channel_skew_s: float = 1e-9
    draws: int = 400

    def analysis_options(self) -> dict[str, Any]:
        """The same values keyed as analysis.params.AnalysisParams options."""
        return {"u_grating_pitch_rel": self.grating_pitch_rel, "u_interferometer_rel": self.interferometer_rel,
                "u_amp_gain_rel": self.amplifier_gain_rel, "u_digitizer_gain_rel": self.digitizer_gain_rel,
                "u_channel_skew_s": self.channel_skew_s, "draws": self.draws}


@dataclass(frozen=True)
class ReferenceCertificateConfig:
    """[[lab.reference_chain]]: one item of the rig's reference chain and its own certificate
    (printed on every certificate as its traceability); due "YYYY-MM-DD"."""

    item: str
    certificate: str
    issued_by: str = ""
    u_rel: float = 0.0  # relative standard uncertainty, k = 1 (0: not stated)
    due: str = ""
    # the [uncertainty] input this item's u_rel is (e.g. "grating_pitch_rel"): a certificate is
    # refused when the two disagree (hopkinson.lab.certificate); "" : not an input of the budget
    budget: str = ""


@dataclass(frozen=True)
class SignatoryConfig:
    """[[lab.signatories]]: a person who may authorise certificates, and their role."""

    name: str
    role: str


@dataclass(frozen=True)
class LabConfig:
    """[lab]: the calibration lab as its certificates name it (hopkinson.lab)."""

    name: str = ""
    address: str = ""
    accreditation: str = ""  # e.g. "DAkkS D-K-12345-01-00" ("" when not accredited)
    certificate_prefix: str = "HB"  # certificates are numbered <prefix>-<year>-<sequence>
    rig: str = ""  # this rig's name in the lab's record ("" : the configuration file's name)
    decision_rule: str = "simple"  # "simple" (ILAC-G8 w = 0) or "guarded" (w = U)
    reference_chain: tuple[ReferenceCertificateConfig, ...] = ()
    signatories: tuple[SignatoryConfig, ...] = ()  # none: no certificate can be authorised
    country: str = ""  # ISO 3166-1 alpha-2 code of the lab (a Digital Calibration Certificate states it)


@dataclass(frozen=True)
class DatabaseConfig:
    """[database]: where the lab's record lives ("" : SQLite in the user's data folder;
    HOPKINSON_DATABASE_URL overrides). Never copied into shot files (it may hold a password)."""

    url: str = ""


# The names of analysis.bar.MATERIALS, written here so that reading a configuration does not
# import the bar model (NumPy and SciPy: half a second for every command); a test holds the two
# equal.
BAR_MATERIALS = ("C45", "Ti-6Al-4V", "PA6", "Al-7075")
BAR_MOUNTS = ("separating", "bonded")  # analysis.bar.geometry.MOUNTS, the same way


@dataclass(frozen=True)
class BarSegmentConfig:
    """A uniform piece of a projectile: material (analysis.bar.MATERIALS), length, diameter."""

    material: str
    length_m: float
    diameter_m: float


@dataclass(frozen=True)
class BarProjectileConfig:
    """[[bar.projectiles]]: one projectile, its segments from the impact face backwards."""

    number: int
    segments: tuple[BarSegmentConfig, ...]
    description: str = ""
    uses_spacer: bool = True
    contact_stiffness_n_m: float = 0.0  # the impact face's contact spring at 1 mm; 0: flat and rigid
    contact_exponent: float = 1.0  # p of F = k·δ₁·(δ/δ₁)^p: 1 a linear spring, 1.5 Hertz's (the paper's projectiles)


@dataclass(frozen=True)
class BarConfig:
    """[bar]: the rig's physics for shot planning and the first shot's pressure (analysis.bar);
    every key has the paper's rig as its default, and no projectiles listed means the paper's three."""

    material: str = "Ti-6Al-4V"
    length_m: float = 1.6
    diameter_m: float = 0.016
    spacer_material: str = "Al-7075"
    spacer_length_m: float = 0.003  # 0: no spacer
    base_length_m: float = 0.010  # the raster base (the bar's material and diameter)
    sensor_mass_kg: float = 0.005
    barrel_length_m: float = 1.5
    launcher_efficiency: float = 0.348
    mount: str = "separating"  # the object on the bar's end: "separating" (flies off) | "bonded" (stays on)
    projectiles: tuple[BarProjectileConfig, ...] = ()

    def rig(self) -> Any:
        """The analysis.bar.BarRig this table describes."""
        from hopkinson.analysis.bar import PAPER_RIG, BarRig, Launcher, Projectile, Segment

        projectiles = tuple(
            Projectile(p.number, p.description or f"projectile No. {p.number}",
                       tuple(Segment(s.material, s.length_m, s.diameter_m) for s in p.segments), p.uses_spacer,
                       p.contact_stiffness_n_m or None, p.contact_exponent)
            for p in self.projectiles) or PAPER_RIG.projectiles
        spacer = Segment(self.spacer_material, self.spacer_length_m, self.diameter_m) if self.spacer_length_m else None
        return BarRig(Segment(self.material, self.length_m, self.diameter_m), spacer,
                      Segment(self.material, self.base_length_m, self.diameter_m), self.sensor_mass_kg, projectiles,
                      Launcher(self.barrel_length_m, self.launcher_efficiency), self.mount)


@dataclass(frozen=True)
class RigConfig:
    """The whole of config/rig.toml, validated."""

    valve_controller: ValveControllerConfig
    digitizer: DigitizerConfig
    amplifier: AmplifierConfig
    limits: LimitsConfig = field(default_factory=LimitsConfig)
    timeouts: TimeoutsConfig = field(default_factory=TimeoutsConfig)
    analysis: AnalysisConfig = field(default_factory=AnalysisConfig)
    uncertainty: UncertaintyConfig = field(default_factory=UncertaintyConfig)
    lab: LabConfig = field(default_factory=LabConfig)
    bar: BarConfig = field(default_factory=BarConfig)
    database: DatabaseConfig = field(default_factory=DatabaseConfig)
    path: str = ""  # where it was loaded from (not a TOML key)

    def snapshot(self) -> dict[str, Any]:
        """The configuration as a JSON-ready dict (for shot files), shaped like the TOML file."""
        data = _jsonable(dataclasses.asdict(self))
        for section in dataclasses.fields(self):
            value = getattr(self, section.name)
            if dataclasses.is_dataclass(value):
                for f in dataclasses.fields(value):
                    if f.metadata.get("inline"):
                        data[section.name].update(data[section.name].pop(f.name))
        del data["database"]  # the URL may hold a password: never in a shot file
        return data


@dataclass(frozen=True)
class _Rule:
    """Checks for one key: inclusive bounds, exclusive lower bound, allowed values."""

    min: float | None = None
    max: float | None = None
    above: float | None = None
    choices: tuple[Any, ...] | None = None
    text: str = ""


_PORT = _Rule(1, 65535)
_ADDRESS = _Rule(0, 65535)
_POSITIVE = _Rule(above=0.0)
_TIMEOUT = _Rule(above=0.0, max=3600.0)

# Key patterns (dotted; list items match without an index) → rule. First match wins.
_BITS = _Rule(-1, 65535, text="-1 (none) or an address 0..65535")
_BAUD = _Rule(choices=(1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600))
_REGISTER_RULES: dict[str, _Rule] = {  # a register table, under valve_controller. and register_map.
    "*.address": _BITS,
    "*.type": _Rule(choices=tuple(REGISTER_TYPES)),
    "*.word_order": _Rule(choices=WORD_ORDERS, text="big: high word first; little: low word first"),
    "*.scale": _Rule(text="non-zero"),
    "*.offset": _Rule(),
    "coils.*": _ADDRESS,
    "discrete_inputs.door_closed": _ADDRESS,
    "discrete_inputs.fixture_clamped": _ADDRESS,
    "discrete_inputs.estop_healthy": _ADDRESS,
    "discrete_inputs.*": _BITS,
    "holding_registers.*": _BITS,
    "input_registers.*": _BITS,
}

# Key patterns (dotted; list items match without an index) → rule. First match wins.
RULES: dict[str, _Rule] = {
    "valve_controller.transport": _Rule(choices=("tcp", "rtu")),
    "valve_controller.port": _PORT,
    "valve_controller.baudrate": _BAUD,
    "valve_controller.parity": _Rule(choices=("N", "E", "O")),
    "valve_controller.stopbits": _Rule(choices=(1, 2)),
    "valve_controller.unit_id": _Rule(1, 247),
    "valve_controller.timeout_s": _TIMEOUT,
    "valve_controller.retries": _Rule(0, 10),
    "valve_controller.watchdog_s": _Rule(0.2, 60.0, text="the controller's link watchdog, seconds"),
    "valve_controller.fire_pulse_s": _Rule(above=0.0, max=10.0),
    **{f"valve_controller.{k}": r for k, r in _REGISTER_RULES.items()},
    "digitizer.timeout_s": _TIMEOUT,
    "digitizer.sample_rate_hz": _Rule(1e3, 1e10),
    "digitizer.record_length": _Rule(16, 100_000_000),
    "digitizer.pre_trigger_fraction": _Rule(0.0, 0.95),
    "digitizer.ch1_range_v": _Rule(above=0.0, max=100.0),
    "digitizer.ch2_range_v": _Rule(above=0.0, max=100.0),
    "digitizer.trigger_slope": _Rule(choices=("POS", "NEG")),
    "digitizer.sample_format": _Rule(choices=("int8", "uint8", "int16", "uint16", "float32")),
    "digitizer.byte_order": _Rule(choices=("little", "big")),
    "digitizer.max_reply_bytes": _Rule(64, 1 << 24),
    "amplifier.baudrate": _BAUD,
    "amplifier.timeout_s": _TIMEOUT,
    "amplifier.retries": _Rule(0, 10),
    "amplifier.gain": _Rule(above=0.0, max=1e6),  # the serial bridge's own steps: _check_amplifier
    "amplifier.excitation_v": _Rule(0.0, EXCITATION_RANGE_V[1]),
    "amplifier.lowpass_hz": _Rule(0.0, 1e8, text="0 (off) or the filter corner"),
    "amplifier.sensitivity_v_per_m_s2": _Rule(0.0, 1.0, text="0 (not entered) or the sensitivity"),
    "lab.decision_rule": _Rule(choices=("simple", "guarded")),
    "lab.reference_chain.u_rel": _Rule(0.0, 1.0),
    "limits.max_pressure_bar": _Rule(above=0.0, max=100.0),
    "bar.material": _Rule(choices=BAR_MATERIALS, text="analysis.bar.MATERIALS"),
    "bar.spacer_material": _Rule(choices=BAR_MATERIALS, text="analysis.bar.MATERIALS"),
    "bar.projectiles.segments.material": _Rule(choices=BAR_MATERIALS, text="analysis.bar.MATERIALS"),
    "bar.spacer_length_m": _Rule(0.0, 1.0, text="0: no spacer"),
    "bar.*length_m": _Rule(above=0.0, max=20.0),
    "bar.*diameter_m": _Rule(above=0.0, max=1.0),
    "bar.projectiles.segments.*": _Rule(above=0.0, max=20.0),
    "bar.sensor_mass_kg": _Rule(0.0, 10.0),
    "bar.mount": _Rule(choices=BAR_MOUNTS),
    "bar.launcher_efficiency": _Rule(above=0.0, max=1.0),
    "bar.projectiles.number": _Rule(1, 3, text="a position of the loader: plans and shots take 1, 2 or 3"),
    "bar.projectiles.contact_stiffness_n_m": _Rule(0.0, 1e12, text="0: flat and rigid"),
    "bar.projectiles.contact_exponent": _Rule(1.0, 3.0, text="1: a linear spring, 1.5: Hertz's"),
    "limits.min_pressure_bar": _Rule(0.0, 100.0),
    "limits.pressure_tolerance_bar": _Rule(above=0.0, max=10.0),
    "limits.fixture_vacuum_max_mbar": _Rule(above=0.0, max=1100.0),
    "limits.vent_done_bar": _Rule(above=0.0, max=10.0),
    "timeouts.*": _TIMEOUT,
    "analysis.grating_pitch_m": _Rule(above=0.0, max=1e-3),
    "analysis.orders": _Rule(-10, 10),
    "analysis.sensitivity_v_per_m_s2": _Rule(above=0.0),
    "analysis.sensitivity_2_v_per_m_s2": _Rule(above=0.0),
    "analysis.amp_gain_2": _Rule(above=0.0, max=1e6),
    "analysis.sample_rate_hz": _Rule(1e3, 1e9),
    "analysis.dcm_widening": _Rule(above=1.0, max=1e3),
    "analysis.dcm_noise_gain_limit": _Rule(above=0.0, max=1e6),
    "uncertainty.*_rel": _Rule(0.0, 0.5),
    "uncertainty.channel_skew_s": _Rule(0.0, 1e-3),
    "uncertainty.draws": _Rule(50, 1_000_000),
    # config/sim.toml
    "servers.modbus_transport": _Rule(choices=("tcp", "rtu")),
    "servers.modbus_port": _Rule(0, 65535),
    "servers.modbus_unit_id": _Rule(1, 247),
    "servers.modbus_baudrate": _BAUD,
    "servers.modbus_parity": _Rule(choices=("N", "E", "O")),
    "servers.modbus_stopbits": _Rule(choices=(1, 2)),
    "servers.amplifier_baudrate": _BAUD,
    "servers.digitizer_port": _Rule(0, 65535),
    "servers.modbus_slow_delay_s": _Rule(0.0, 60.0),
    "world.time_scale": _Rule(above=0.0, max=10_000.0),
    "world.seed": _Rule(0, 2**63),
    "world.pneumatics.atmosphere_mbar": _Rule(above=0.0, max=2000.0),
    "world.pneumatics.watchdog_s": _Rule(0.2, 60.0),
    "world.pneumatics.*_bar": _Rule(0.0, 100.0),
    "world.pneumatics.*_mbar": _Rule(0.0, 2000.0),
    "world.pneumatics.*_s": _POSITIVE,
    "world.pneumatics.*_bar_s": _POSITIVE,
    "world.pneumatics.*_mbar_s": _POSITIVE,
    "world.launcher.projectile": _Rule(choices=(1, 2, 3)),
    "world.launcher.pulse_width_s": _Rule(above=0.0, max=0.01),
    "world.launcher.*": _POSITIVE,
    "world.accelerometer.modes.natural_frequency_hz": _Rule(above=0.0, max=1e7),
    "world.accelerometer.modes.damping_ratio": _Rule(above=0.0, max=10.0),
    "world.accelerometer.zero_shift_m_s2": _Rule(),
    "world.accelerometer.bridge_offset_v": _Rule(-1.0, 1.0),
    "world.accelerometer.nonlinearity_per_m_s2": _Rule(-1e-5, 1e-5, text="per m/s2 of |a|; 0 = linear"),
    "world.accelerometer.*": _POSITIVE,
    "world.amplifier.gain": _Rule(choices=GAINS),
    "world.amplifier.excitation_v": _Rule(*EXCITATION_RANGE_V),
    "world.amplifier.lowpass_hz": _Rule(choices=(0.0, *LOWPASS_HZ)),
    "world.amplifier.lowpass_order": _Rule(1, 8),
    "world.amplifier.auto_zero_residual_v": _Rule(-1.0, 1.0),
    "world.amplifier.output_limit_v": _POSITIVE,
    "world.signals.orders": _Rule(-10, 10),
    "world.signals.pm_dc_offset_v": _Rule(-10.0, 10.0),
    "world.signals.pm_fluctuation": _Rule(0.0, 1.0),
    "world.signals.response_coloured_pole": _Rule(0.0, 0.999),
    "world.signals.*_snr_db": _Rule(0.0, 200.0, text="0 (no noise) .. 200 dB"),
    "world.signals.pulse_bipolar_ratio": _Rule(0.0, 0.95),
    "world.signals.channel_skew_s": _Rule(-1e-6, 1e-6),
    "world.signals.response_drift_v_per_s": _Rule(-1e3, 1e3),
    "world.signals.quadrature_offset_v": _Rule(-10.0, 10.0),
    "world.signals.quadrature_error_deg": _Rule(-45.0, 45.0),
    "world.signals.quadrature_gain_ratio": _Rule(above=0.0, max=10.0),
    "world.signals.*": _POSITIVE,
    "world.accelerometer_2.modes.natural_frequency_hz": _Rule(above=0.0, max=1e7),
    "world.accelerometer_2.modes.damping_ratio": _Rule(above=0.0, max=10.0),
    "world.accelerometer_2.zero_shift_m_s2": _Rule(),
    "world.accelerometer_2.lowpass_hz": _Rule(0.0, 1e8, text="0 (off) or the filter corner"),
    "world.accelerometer_2.lowpass_order": _Rule(1, 8),
    "world.accelerometer_2.*": _POSITIVE,
    "world.realism.pulse_source": _Rule(choices=("ideal", "bar")),
    "world.realism.bar_mount": _Rule(choices=BAR_MOUNTS),
    "world.realism.speed_scatter_rel": _Rule(0.0, 0.2),
    "world.realism.bar_ringing.amplitude_rel": _Rule(0.0, 0.5),
    "world.realism.bar_ringing.frequencies_hz": _Rule(above=0.0, max=1e6),
    "world.realism.bar_ringing.base_gain": _Rule(0.0, 2.0),
    "world.realism.mount.frequency_ratio": _Rule(0.5, 2.0),
    "world.realism.mount.asymmetry_rel": _Rule(-0.5, 0.5),
    "world.realism.transverse.sensitivity_rel": _Rule(0.0, 0.5),
    "world.realism.transverse.lateral_peak_rel": _Rule(0.0, 100.0),
    "world.realism.reference.noise_rel": _Rule(0.0, 0.5),
    "world.realism.reference.flight_noise_factor": _Rule(1.0, 1000.0),
    "world.realism.reference.lowpass_order": _Rule(1, 8),
    "world.realism.reference.delay_s": _Rule(-1e-5, 1e-5),
    "world.realism.reference.onset_glitches": _Rule(0, 100),
    "world.realism.reference.onset_dip": _Rule(0.0, 0.99),
    "world.realism.reference.onset_glitch_rad": _Rule(0.0, 100.0),
    "world.realism.*.*_s": _POSITIVE,
    "world.realism.*.*_hz": _POSITIVE,
    **{f"register_map.{k}": r for k, r in _REGISTER_RULES.items()},
}


# -- public loaders ---------------------------------------------------------------------------
def load_rig_config(path: str | Path) -> RigConfig:
    """Read and validate config/rig.toml (or a variant); ConfigError on anything wrong."""
    path = Path(path)
    data, _ = read_toml(path)
    config = _build(RigConfig, data, path, "", skip=("path",))
    _check_rig(config, path)
    _check_limits_stated(data, path)
    return dataclasses.replace(config, path=str(path))


def load_sim_config(path: str | Path) -> SimConfig:
    """Read and validate config/sim.toml; ConfigError on anything wrong."""
    # Imported here: the simulator's servers are only loaded by the commands that run them.
    from hopkinson.drivers.sim.scpi_digitizer import SIM_DIALECTS
    from hopkinson.drivers.sim.simulated_rig import SimConfig

    path = Path(path)
    data, _ = read_toml(path)
    register_map = _build(RegisterMap, data.pop("register_map", {}), path, "register_map")
    _check_register_map(register_map, path, "register_map")
    config = _build(SimConfig, data, path, "", skip=("register_map",))
    if config.servers.digitizer_dialect not in SIM_DIALECTS:
        raise ConfigError(f"{path}: servers.digitizer_dialect: must be one of {', '.join(SIM_DIALECTS)}, "
                          f"got {config.servers.digitizer_dialect!r}")
    if not config.world.accelerometer.modes:
        raise ConfigError(f"{path}: world.accelerometer.modes: at least one mode is needed")
    if config.world.accelerometer_2.enabled and not config.world.accelerometer_2.modes:
        raise ConfigError(f"{path}: world.accelerometer_2.modes: at least one mode is needed")
    _check_orders(config.world.signals.orders, path, "world.signals.orders")
    return dataclasses.replace(config, register_map=controller_map_of(register_map))


def controller_map_of(register_map: RegisterMap) -> dict[str, dict[str, Any]]:
    """The simulated controller's map (drivers/sim/controller_map.py) for a driver's map."""
    from hopkinson.drivers.sim.controller_map import Point

    return {table: {name: Point(**dataclasses.asdict(entry)) if isinstance(entry, Register) else Point(entry)
                    for name, entry in entries.items()}
            for table, entries in register_map.blocks().items()}


def register_map_of(controller_map: dict[str, dict[str, Any]]) -> RegisterMap:
    """The driver's map that reaches a simulated controller laid out by `controller_map`."""
    tables = {}
    for block in dataclasses.fields(RegisterMap):
        table_type = typing.get_type_hints(RegisterMap)[block.name]
        points = controller_map.get(block.name, {})
        values: dict[str, Any] = {}
        for f in dataclasses.fields(table_type):
            point = points.get(f.name)
            if typing.get_type_hints(table_type)[f.name] is Register:
                values[f.name] = Register(**dataclasses.asdict(point)) if point is not None else Register()
            else:
                values[f.name] = point.address if point is not None else -1
        tables[block.name] = table_type(**values)
    return RegisterMap(**tables)


# -- checks across keys -------------------------------------------------------------------------
def _check_limits_stated(data: dict[str, Any], path: Path) -> None:
    """A rig's file states every safety limit itself: the built-in values are the simulated
    rig's (rig-sim.toml states them too), never a real rig's by default."""
    limits = data.get("limits")
    missing = [f.name for f in dataclasses.fields(LimitsConfig) if not isinstance(limits, dict) or f.name not in limits]
    if missing:
        where = "[limits]" if not isinstance(limits, dict) else f"limits.{missing[0]}"
        raise ConfigError(f"{path}: {where}: the rig must state its safety limits: add [limits] with "
                          f"{', '.join(f'{m} = …' for m in missing)} (see config/rig.toml)")


def _check_rig(config: RigConfig, path: Path) -> None:
    limits = config.limits
    if limits.min_pressure_bar >= limits.max_pressure_bar:
        raise ConfigError(f"{path}: limits.min_pressure_bar: must be below limits.max_pressure_bar "
                          f"({limits.min_pressure_bar:g} >= {limits.max_pressure_bar:g})")
    _check_orders(config.analysis.orders, path, "analysis.orders")
    _check_valve_controller(config.valve_controller, path)
    _check_thresholds(config, path)
    _check_amplifier(config.amplifier, path)
    _check_driver(config.digitizer.driver, ("scpi",), path, "digitizer")
    _check_lab(config.lab, config.database, path)


def _check_lab(lab: LabConfig, database: DatabaseConfig, path: Path) -> None:
    if not re.fullmatch(r"[A-Z0-9]{1,12}", lab.certificate_prefix):
        raise ConfigError(f"{path}: lab.certificate_prefix: 1 to 12 capital letters or digits, "
                          f"got {lab.certificate_prefix!r}")
    for i, link in enumerate(lab.reference_chain):
        if not link.item.strip() or not link.certificate.strip():
            raise ConfigError(f"{path}: lab.reference_chain[{i}]: item and certificate must not be empty")
        if link.due:
            try:
                date.fromisoformat(link.due)
            except ValueError:
                raise ConfigError(f"{path}: lab.reference_chain[{i}].due: a date YYYY-MM-DD (as a string), "
                                  f"got {link.due!r}") from None
        budget_keys = [f.name for f in dataclasses.fields(UncertaintyConfig) if f.name.endswith("_rel")]
        if link.budget and link.budget not in budget_keys:
            raise ConfigError(f"{path}: lab.reference_chain[{i}].budget: one of {', '.join(budget_keys)} "
                              f"(the [uncertainty] input it is), got {link.budget!r}")
    if lab.country and not re.fullmatch(r"[A-Z]{2}", lab.country):
        raise ConfigError(f"{path}: lab.country: an ISO 3166-1 alpha-2 code such as \"DE\", got {lab.country!r}")
    for i, person in enumerate(lab.signatories):
        if not person.name.strip() or not person.role.strip():
            raise ConfigError(f"{path}: lab.signatories[{i}]: name and role must not be empty")
    scheme = database.url.split(":", 1)[0].split("+", 1)[0]
    if database.url and scheme not in ("sqlite", "postgresql", "postgres"):
        raise ConfigError(f"{path}: database.url: a sqlite:///FILE or postgresql://… URL, got scheme {scheme!r}")


def _check_valve_controller(vc: ValveControllerConfig, path: Path) -> None:
    _check_driver(vc.driver, ("modbus",), path, "valve_controller")
    if vc.driver != "modbus":
        return
    if vc.options:
        raise ConfigError(f"{path}: valve_controller.options: only for a lab's own driver (driver = "
                          f"\"package.module:Class\"); the modbus driver takes the keys of [valve_controller]")
    if vc.transport == "tcp" and not vc.host:
        raise ConfigError(f"{path}: valve_controller.host: missing key (the controller's address on Modbus TCP)")
    if vc.transport == "rtu" and not vc.serial_port:
        raise ConfigError(f"{path}: valve_controller.serial_port: missing key (the RS-485 port for Modbus RTU)")
    _check_register_map(vc.register_map, path, "valve_controller")
    m = vc.register_map
    required = {"holding_registers.heartbeat": m.holding_registers.heartbeat,
                "input_registers.watchdog_state": m.input_registers.watchdog_state,
                "holding_registers.fire_pulse_ms": m.holding_registers.fire_pulse_ms.address,
                "input_registers.fire_pulse_count": m.input_registers.fire_pulse_count.address}
    for key, address in required.items():
        if address < 0:
            raise ConfigError(f"{path}: valve_controller.{key}: missing (the controller's link watchdog and "
                              "its fire pulse are what keep the rig safe when this computer fails; map them)")
    for key, register, value, unit in (
            ("holding_registers.fire_pulse_ms", m.holding_registers.fire_pulse_ms, vc.fire_pulse_s * 1000, "ms"),
            ("holding_registers.watchdog_ms", m.holding_registers.watchdog_ms, vc.watchdog_s * 1000, "ms")):
        _check_fits(register, value, unit, path, f"valve_controller.{key}",
                    "valve_controller.fire_pulse_s" if "fire" in key else "valve_controller.watchdog_s")
    if vc.fire_pulse_s >= vc.watchdog_s:
        raise ConfigError(f"{path}: valve_controller.fire_pulse_s: {vc.fire_pulse_s:g} s must be shorter than "
                          f"valve_controller.watchdog_s ({vc.watchdog_s:g} s)")


def _check_thresholds(config: RigConfig, path: Path) -> None:
    """Thresholds against the pressure limits, the gauge resolution and the registers."""
    limits = config.limits
    vc = config.valve_controller
    if vc.driver == "modbus":
        m = vc.register_map
        for key, register, value, unit in (
                ("holding_registers.pressure_setpoint", m.holding_registers.pressure_setpoint,
                 limits.max_pressure_bar, "bar"),
                ("input_registers.reservoir_pressure", m.input_registers.reservoir_pressure,
                 limits.max_pressure_bar, "bar"),
                ("input_registers.fixture_vacuum", m.input_registers.fixture_vacuum,
                 limits.fixture_vacuum_max_mbar, "mbar")):
            _check_fits(register, value, unit, path, f"valve_controller.{key}",
                        "limits.fixture_vacuum_max_mbar" if "vacuum" in key else "limits.max_pressure_bar")
        low, _ = m.input_registers.reservoir_pressure.value_range()
        if low > 0:
            raise ConfigError(f"{path}: valve_controller.input_registers.reservoir_pressure: the gauge cannot "
                              f"read 0 bar (lowest {low:g} bar), so venting could never be confirmed")
    resolution = vc.gauge_resolution_bar
    if limits.vent_done_bar >= limits.min_pressure_bar:
        raise ConfigError(f"{path}: limits.vent_done_bar: {limits.vent_done_bar:g} bar must be below "
                          f"limits.min_pressure_bar ({limits.min_pressure_bar:g} bar): a reservoir this full "
                          "is not vented")
    if limits.pressure_tolerance_bar > limits.min_pressure_bar / 2:
        raise ConfigError(f"{path}: limits.pressure_tolerance_bar: {limits.pressure_tolerance_bar:g} bar is more "
                          f"than half of limits.min_pressure_bar ({limits.min_pressure_bar:g} bar): a shot could "
                          "count as charged far below its pressure")
    for key in ("vent_done_bar", "pressure_tolerance_bar"):
        if getattr(limits, key) < resolution:
            raise ConfigError(f"{path}: limits.{key}: {getattr(limits, key):g} bar is finer than the "
                              f"reservoir gauge resolves ({resolution:g} bar per count)")


def _check_fits(register: Register, value: float, unit: str, path: Path, key: str, setting: str) -> None:
    if register.present and not register.holds(value):
        low, high = register.value_range()
        raise ConfigError(f"{path}: {setting}: {value:g} {unit} does not fit {key} "
                          f"({register.type}, scale {register.scale:g}: {low:g} .. {high:g} {unit})")


def _check_amplifier(amp: AmplifierConfig, path: Path) -> None:
    _check_driver(amp.driver, ("serial-bridge", "manual"), path, "amplifier")
    if amp.driver == "serial-bridge":
        if not amp.port:
            raise ConfigError(f"{path}: amplifier.port: missing key (the serial bridge amplifier's port)")
        for key, value, allowed in (("gain", amp.gain, GAINS), ("lowpass_hz", amp.lowpass_hz, (0.0, *LOWPASS_HZ))):
            if value not in allowed:
                shown = ", ".join(f"{a:g}" for a in allowed)
                raise ConfigError(f"{path}: amplifier.{key}: the serial bridge amplifier has {shown}; got {value:g}")
        low, high = EXCITATION_RANGE_V
        if not low <= amp.excitation_v <= high:
            raise ConfigError(f"{path}: amplifier.excitation_v: the serial bridge amplifier has {low:g} .. {high:g} V,"
                              f" got {amp.excitation_v:g}")
    if amp.driver in ("serial-bridge", "manual") and amp.options:
        raise ConfigError(f"{path}: amplifier.options: only for a lab's own driver (driver = \"package.module:Class\")")


def _check_driver(driver: str, built_in: tuple[str, ...], path: Path, section: str) -> None:
    """A lab's driver class must import and have its role's methods (rig/driver_classes.py)."""
    if driver not in built_in:
        from hopkinson.rig.driver_classes import driver_class

        driver_class(driver, section, f"{path}: {section}.driver")


def _check_register_map(register_map: RegisterMap, path: Path, prefix: str) -> None:
    overlaps = register_map.overlaps()
    if overlaps:
        raise ConfigError(f"{path}: {prefix}: {overlaps[0]}")


def _check_orders(orders: tuple[int, int], path: Path, key: str) -> None:
    if orders[0] == orders[1]:
        raise ConfigError(f"{path}: {key}: the two diffraction orders must differ, got {list(orders)}")


# -- the generic reader ---------------------------------------------------------------------------
def _build(cls: type, table: Any, path: Path, prefix: str, skip: tuple[str, ...] = ()) -> Any:
    """Make dataclass `cls` from a TOML table, checking keys, types and RULES.

    A field with metadata {"inline": True} is a dataclass whose own fields sit in this same
    table (the register map's four tables in [valve_controller])."""
    where = prefix or "top level"
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: {prefix}: must be a table, got {_type_name(table)}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name not in skip}
    inline = {name: f for name, f in fields.items() if f.metadata.get("inline")}
    keys = {name for name in fields if name not in inline}
    for f in inline.values():
        keys.update(g.name for g in dataclasses.fields(hints[f.name]))
    for key in table:
        if key not in keys:
            kind = "section" if not prefix else "key"
            raise ConfigError(f"{path}: {_join(prefix, key)}: unknown {kind} in {where} (known: {', '.join(sorted(keys))})")
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        key = _join(prefix, name)
        if name in inline:
            own = {g.name for g in dataclasses.fields(hints[name])}
            kwargs[name] = _build(hints[name], {k: v for k, v in table.items() if k in own}, path, prefix)
            continue
        if name not in table:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                kind = "section" if dataclasses.is_dataclass(hints[name]) else "key"
                raise ConfigError(f"{path}: {key}: missing {kind}")
            continue
        kwargs[name] = _convert(hints[name], table[name], path, key)
    try:
        return cls(**kwargs)
    except ValueError as exc:  # a dataclass's own check (e.g. a register's scale of 0)
        raise ConfigError(f"{path}: {prefix or where}: {exc}") from None


def _convert(tp: Any, value: Any, path: Path, key: str) -> Any:
    if tp is Register and isinstance(value, int) and not isinstance(value, bool):
        _apply_rule(value, value, path, f"{key}.address")
        return Register(value)
    if dataclasses.is_dataclass(tp):
        return _build(tp, value, path, key)
    origin = typing.get_origin(tp)
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{path}: {key}: must be a table, got {_type_name(value)}")
        return dict(value)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list):
            raise ConfigError(f"{path}: {key}: must be an array, got {_type_name(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            item_types = [args[0]] * len(value)
        else:
            if len(value) != len(args):
                raise ConfigError(f"{path}: {key}: must have {len(args)} items, got {len(value)}")
            item_types = list(args)
        return tuple(_convert(t, v, path, f"{key}[{i}]") for i, (t, v) in enumerate(zip(item_types, value, strict=True)))
    if origin in (typing.Union, types.UnionType):
        raise TypeError(f"unsupported config type {tp} for {key}")
    out = _scalar(tp, value, path, key)
    _apply_rule(out, value, path, key)
    return out


def _scalar(tp: Any, value: Any, path: Path, key: str) -> Any:
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: {key}: must be true or false, got {_type_name(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: {key}: must be an integer, got {_type_name(value)}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{path}: {key}: must be a number, got {_type_name(value)}")
        if not math.isfinite(value):
            raise ConfigError(f"{path}: {key}: must be a finite number, got {value}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: {key}: must be a string, got {_type_name(value)}")
        return value
    raise TypeError(f"unsupported config type {tp} for {key}")


def _apply_rule(value: Any, written: Any, path: Path, key: str) -> None:
    """Check `value` against the first matching rule; messages quote the value as `written`."""
    pattern_key = _strip_indices(key)
    rule = next((r for pattern, r in RULES.items() if fnmatchcase(pattern_key, pattern)), None)
    if rule is None:
        return
    hint = f" ({rule.text})" if rule.text else ""
    if rule.choices is not None and value not in rule.choices:
        shown = ", ".join(f"{c:g}" if isinstance(c, float) else str(c) for c in rule.choices)
        raise ConfigError(f"{path}: {key}: must be one of {shown}{hint}, got {written!r}")
    if isinstance(value, str | bool):
        return
    if rule.above is not None and not value > rule.above:
        raise ConfigError(f"{path}: {key}: must be greater than {rule.above:g}{hint}, got {written!r}")
    if rule.min is not None and value < rule.min:
        raise ConfigError(f"{path}: {key}: must be at least {rule.min:g}{hint}, got {written!r}")
    if rule.max is not None and value > rule.max:
        raise ConfigError(f"{path}: {key}: must be at most {rule.max:g}{hint}, got {written!r}")


def _strip_indices(key: str) -> str:
    out, depth = [], 0
    for ch in key:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
        elif depth == 0:
            out.append(ch)
    return "".join(out)


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _type_name(value: Any) -> str:
    """How a TOML value is described in messages, e.g. "a string ('5020')"."""
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array",
             dict: "a table"}
    name = names.get(type(value), type(value).__name__)
    return name if isinstance(value, dict | list) else f"{name} ({value!r})"


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    return obj
