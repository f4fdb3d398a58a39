"""Rig configuration (config/rig.toml) and simulator configuration (config/sim.toml).

`load_rig_config(path) -> RigConfig` reads the TOML file and returns typed, frozen dataclasses,
one per section:

    [valve_controller]   host, port, device_id, timeout_s, retries
      [valve_controller.coils | .discrete_inputs | .holding_registers | .input_registers | .scales]
    [digitizer]          resource, timeout_s, sample_rate_hz, record_length, pre_trigger_fraction,
                         ch1_range_v, ch2_range_v, trigger_source, trigger_level_v, trigger_slope
    [amplifier]          port, baudrate, timeout_s, retries, gain, excitation_v, lowpass_hz
    [limits]             max_pressure_bar, min_pressure_bar, fixture_vacuum_max_mbar, ...
    [timeouts]           check_s, evacuate_s, charge_s, arm_s, fire_s, capture_s, safe_s, store_s, analyse_s
    [analysis]           grating_pitch_m, orders, sensitivity_v_per_m_s2, sample_rate_hz

`load_sim_config(path) -> SimConfig` does the same for the simulator's file ([servers],
[world] with its sub-tables, [register_map]).

Validation happens at load: an unknown section or key, a wrong type or a value out of range
raises ConfigError naming the file, the key (dotted, e.g. "valve_controller.coils.fire_valve")
and the reason. The rules are the RULES table below (one line per key pattern), applied by
one generic reader of dataclasses (`_build`), so every section is checked the same way.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from hopkinson.drivers.amplifier import EXCITATION_RANGE_V, GAINS, LOWPASS_HZ
from hopkinson.drivers.valve_controller import (
    CoilMap,
    DiscreteInputMap,
    HoldingRegisterMap,
    InputRegisterMap,
    RegisterMap,
    ScaleMap,
)
from hopkinson.rig.errors import ConfigError

if typing.TYPE_CHECKING:
    from hopkinson.drivers.sim.simulated_rig import SimConfig


@dataclass(frozen=True)
class ValveControllerConfig:
    """[valve_controller]: Modbus TCP address and register map of the gas/vacuum controller."""

    host: str
    port: int = 502
    device_id: int = 1
    timeout_s: float = 1.0
    retries: int = 0
    coils: CoilMap = field(default_factory=CoilMap)
    discrete_inputs: DiscreteInputMap = field(default_factory=DiscreteInputMap)
    holding_registers: HoldingRegisterMap = field(default_factory=HoldingRegisterMap)
    input_registers: InputRegisterMap = field(default_factory=InputRegisterMap)
    scales: ScaleMap = field(default_factory=ScaleMap)

    @property
    def register_map(self) -> RegisterMap:
        return RegisterMap(self.coils, self.discrete_inputs, self.holding_registers,
                           self.input_registers, self.scales)


@dataclass(frozen=True)
class DigitizerConfig:
    """[digitizer]: VISA resource and acquisition settings (channel 1 PM beat, 2 amplifier)."""

    resource: str
    timeout_s: float = 5.0
    sample_rate_hz: float = 100e6
    record_length: int = 200_000
    pre_trigger_fraction: float = 0.1
    ch1_range_v: float = 1.0
    ch2_range_v: float = 10.0
    trigger_source: str = "CH2"
    trigger_level_v: float = 0.2
    trigger_slope: str = "POS"

    @property
    def pre_trigger_samples(self) -> int:
        return min(int(round(self.pre_trigger_fraction * self.record_length)), self.record_length - 1)


@dataclass(frozen=True)
class AmplifierConfig:
    """[amplifier]: serial port and settings of the bridge amplifier."""

    port: str
    baudrate: int = 115200
    timeout_s: float = 1.0
    retries: int = 1
    gain: float = 10.0
    excitation_v: float = 5.0
    lowpass_hz: float = 200_000.0  # 0 = filter off


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


@dataclass(frozen=True)
class RigConfig:
    """The whole of config/rig.toml, validated."""

    valve_controller: ValveControllerConfig
    digitizer: DigitizerConfig
    amplifier: AmplifierConfig
    limits: LimitsConfig = field(default_factory=LimitsConfig)
    timeouts: TimeoutsConfig = field(default_factory=TimeoutsConfig)
    analysis: AnalysisConfig = field(default_factory=AnalysisConfig)
    path: str = ""  # where it was loaded from (not a TOML key)

    def snapshot(self) -> dict[str, Any]:
        """The configuration as a JSON-ready dict (for shot files)."""
        return _jsonable(dataclasses.asdict(self))


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
RULES: dict[str, _Rule] = {
    "valve_controller.port": _PORT,
    "valve_controller.device_id": _Rule(0, 247),
    "valve_controller.timeout_s": _TIMEOUT,
    "valve_controller.retries": _Rule(0, 10),
    "valve_controller.holding_registers.projectile": _Rule(-1, 65535, text="-1 (none) or an address 0..65535"),
    "valve_controller.coils.*": _ADDRESS,
    "valve_controller.discrete_inputs.*": _ADDRESS,
    "valve_controller.holding_registers.*": _ADDRESS,
    "valve_controller.input_registers.*": _ADDRESS,
    "valve_controller.scales.*": _POSITIVE,
    "digitizer.timeout_s": _TIMEOUT,
    "digitizer.sample_rate_hz": _Rule(1e3, 1e10),
    "digitizer.record_length": _Rule(16, 100_000_000),
    "digitizer.pre_trigger_fraction": _Rule(0.0, 0.95),
    "digitizer.ch1_range_v": _Rule(above=0.0, max=100.0),
    "digitizer.ch2_range_v": _Rule(above=0.0, max=100.0),
    "digitizer.trigger_source": _Rule(choices=("CH1", "CH2", "EXT")),
    "digitizer.trigger_slope": _Rule(choices=("POS", "NEG")),
    "amplifier.baudrate": _Rule(choices=(9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)),
    "amplifier.timeout_s": _TIMEOUT,
    "amplifier.retries": _Rule(0, 10),
    "amplifier.gain": _Rule(choices=GAINS),
    "amplifier.excitation_v": _Rule(*EXCITATION_RANGE_V),
    "amplifier.lowpass_hz": _Rule(choices=(0.0, *LOWPASS_HZ), text="0 (off) or one of the filter corners"),
    "limits.max_pressure_bar": _Rule(above=0.0, max=100.0),
    "limits.min_pressure_bar": _Rule(0.0, 100.0),
    "limits.pressure_tolerance_bar": _Rule(above=0.0, max=10.0),
    "limits.fixture_vacuum_max_mbar": _Rule(above=0.0, max=1100.0),
    "limits.vent_done_bar": _Rule(above=0.0, max=10.0),
    "timeouts.*": _TIMEOUT,
    "analysis.grating_pitch_m": _Rule(above=0.0, max=1e-3),
    "analysis.orders": _Rule(-10, 10),
    "analysis.sensitivity_v_per_m_s2": _Rule(above=0.0),
    "analysis.sample_rate_hz": _Rule(1e3, 1e9),
    # config/sim.toml
    "servers.modbus_port": _Rule(0, 65535),
    "servers.digitizer_port": _Rule(0, 65535),
    "servers.modbus_slow_delay_s": _Rule(0.0, 60.0),
    "world.time_scale": _Rule(above=0.0, max=10_000.0),
    "world.seed": _Rule(0, 2**63),
    "world.pneumatics.atmosphere_mbar": _Rule(above=0.0, max=2000.0),
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
    "world.signals.*": _POSITIVE,
    "register_map.coils.*": _ADDRESS,
    "register_map.discrete_inputs.*": _ADDRESS,
    "register_map.holding_registers.projectile": _Rule(-1, 65535),
    "register_map.holding_registers.*": _ADDRESS,
    "register_map.input_registers.*": _ADDRESS,
    "register_map.scales.*": _POSITIVE,
}


# -- public loaders ---------------------------------------------------------------------------
def load_rig_config(path: str | Path) -> RigConfig:
    """Read and validate config/rig.toml (or a variant); ConfigError on anything wrong."""
    path = Path(path)
    data = _read_toml(path)
    config = _build(RigConfig, data, path, "", skip=("path",))
    _check_rig(config, path)
    return dataclasses.replace(config, path=str(path))


def load_sim_config(path: str | Path) -> SimConfig:
    """Read and validate config/sim.toml; ConfigError on anything wrong."""
    # Imported here: the simulator's servers are only loaded by the commands that run them.
    from hopkinson.drivers.sim.simulated_rig import SimConfig

    path = Path(path)
    config = _build(SimConfig, _read_toml(path), path, "")
    _check_register_map(config.register_map, path, "register_map")
    if not config.world.accelerometer.modes:
        raise ConfigError(f"{path}: world.accelerometer.modes: at least one mode is needed")
    _check_orders(config.world.signals.orders, path, "world.signals.orders")
    return config


# -- checks across keys -------------------------------------------------------------------------
def _check_rig(config: RigConfig, path: Path) -> None:
    limits = config.limits
    if limits.min_pressure_bar >= limits.max_pressure_bar:
        raise ConfigError(f"{path}: limits.min_pressure_bar: must be below limits.max_pressure_bar "
                          f"({limits.min_pressure_bar:g} >= {limits.max_pressure_bar:g})")
    _check_register_map(config.valve_controller.register_map, path, "valve_controller")
    _check_orders(config.analysis.orders, path, "analysis.orders")
    scale = config.valve_controller.scales.pressure_bar_per_count
    if limits.max_pressure_bar / scale > 0xFFFF:
        raise ConfigError(f"{path}: limits.max_pressure_bar: {limits.max_pressure_bar:g} bar does not fit the "
                          f"16-bit set-point register at {scale:g} bar per count")


def _check_register_map(register_map: RegisterMap, path: Path, prefix: str) -> None:
    for block in ("coils", "discrete_inputs", "holding_registers", "input_registers"):
        table = dataclasses.asdict(getattr(register_map, block))
        seen: dict[int, str] = {}
        for name, address in table.items():
            if address < 0:
                continue
            if address in seen:
                raise ConfigError(f"{path}: {prefix}.{block}.{name}: address {address} is also "
                                  f"{prefix}.{block}.{seen[address]}")
            seen[address] = name


def _check_orders(orders: tuple[int, int], path: Path, key: str) -> None:
    if orders[0] == orders[1]:
        raise ConfigError(f"{path}: {key}: the two diffraction orders must differ, got {list(orders)}")


# -- the generic reader ---------------------------------------------------------------------------
def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None


def _build(cls: type, table: Any, path: Path, prefix: str, skip: tuple[str, ...] = ()) -> Any:
    """Make dataclass `cls` from a TOML table, checking keys, types and RULES."""
    where = prefix or "top level"
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: {prefix}: must be a table, got {_type_name(table)}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name not in skip}
    for key in table:
        if key not in fields:
            kind = "section" if not prefix else "key"
            known = ", ".join(fields)
            raise ConfigError(f"{path}: {_join(prefix, key)}: unknown {kind} in {where} (known: {known})")
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        key = _join(prefix, name)
        if name not in table:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                kind = "section" if dataclasses.is_dataclass(hints[name]) else "key"
                raise ConfigError(f"{path}: {key}: missing {kind}")
            continue
        kwargs[name] = _convert(hints[name], table[name], path, key)
    return cls(**kwargs)


def _convert(tp: Any, value: Any, path: Path, key: str) -> Any:
    if dataclasses.is_dataclass(tp):
        return _build(tp, value, path, key)
    origin = typing.get_origin(tp)
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
