"""rig.toml checked as a whole, after each key has passed its own declaration (rig/config.py):
thresholds against the pressure limits, the gauge's resolution and what each register can hold,
the register map for overlaps and for the registers the safety functions need, each driver's
own keys, and the safety limits stated in the file itself. Every failure is a ConfigError
naming the file, the key and the reason."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path
from typing import Any

from hopkinson.drivers.fire_styles import FIRE_STYLE_DOC, FireStyle
from hopkinson.drivers.registers import Register, RegisterMap
from hopkinson.rig.errors import ConfigError

if typing.TYPE_CHECKING:
    from hopkinson.rig.config import AmplifierConfig, RigConfig, ValveControllerConfig


def check_limits_stated(data: dict[str, Any], path: Path) -> None:
    """A rig's file states every safety limit itself: the built-in values are the simulated
    rig's (rig-sim.toml states them too), never a real rig's by default."""
    from hopkinson.rig.config import LimitsConfig

    limits = data.get("limits")
    missing = [f.name for f in dataclasses.fields(LimitsConfig) if not isinstance(limits, dict) or f.name not in limits]
    if missing:
        where = "[limits]" if not isinstance(limits, dict) else f"limits.{missing[0]}"
        raise ConfigError(f"{path}: {where}: the rig must state its safety limits: add [limits] with "
                          f"{', '.join(f'{m} = …' for m in missing)} (see config/rig.toml)")


def check_rig(config: RigConfig, path: Path) -> None:
    limits = config.limits
    if limits.min_pressure_bar >= limits.max_pressure_bar:
        raise ConfigError(f"{path}: limits.min_pressure_bar: must be below limits.max_pressure_bar "
                          f"({limits.min_pressure_bar:g} >= {limits.max_pressure_bar:g})")
    _check_valve_controller(config.valve_controller, path)
    _check_thresholds(config, path)
    check_plausibility(config, path)
    _check_amplifier(config.amplifier, path)
    _check_driver(config.digitizer.driver, ("scpi",), path, "digitizer")


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
    check_register_map(vc.register_map, path, "valve_controller")
    m = vc.register_map
    required = {"holding_registers.heartbeat": m.holding_registers.heartbeat,
                "input_registers.watchdog_state": m.input_registers.watchdog_state}
    if vc.fire_style == FireStyle.PULSE_REGISTER:
        required["holding_registers.fire_pulse_ms"] = m.holding_registers.fire_pulse_ms.address
        required["input_registers.fire_pulse_count"] = m.input_registers.fire_pulse_count.address
    for key, address in required.items():
        if address < 0:
            raise ConfigError(f"{path}: valve_controller.{key}: missing (the controller's link watchdog and "
                              "its fire pulse are what keep the rig safe when this computer fails; map them)")
    check_fire_style(vc, path)
    for key, register, value, unit in (
            ("holding_registers.fire_pulse_ms", m.holding_registers.fire_pulse_ms, vc.fire_pulse_s * 1000, "ms"),
            ("holding_registers.watchdog_ms", m.holding_registers.watchdog_ms, vc.watchdog_s * 1000, "ms")):
        _check_fits(register, value, unit, path, f"valve_controller.{key}",
                    "valve_controller.fire_pulse_s" if "fire" in key else "valve_controller.watchdog_s")
    if vc.fire_pulse_s >= vc.watchdog_s:
        raise ConfigError(f"{path}: valve_controller.fire_pulse_s: {vc.fire_pulse_s:g} s must be shorter than "
                          f"valve_controller.watchdog_s ({vc.watchdog_s:g} s)")


def check_fire_style(vc: ValveControllerConfig, path: Path) -> None:
    """The signals each fire style needs, and the lab's word for a pulse timed by this computer."""
    style = FireStyle(vc.fire_style)
    h = vc.register_map.holding_registers
    why = f'valve_controller.fire_style = "{style}" ({FIRE_STYLE_DOC})'
    if style.writes_preset and not h.fire_pulse_ms.present:
        raise ConfigError(f"{path}: valve_controller.holding_registers.fire_pulse_ms: missing: {why} writes the "
                          "pulse length there")
    if style == FireStyle.PRESET_AND_COMMAND and h.fire_command < 0:
        raise ConfigError(f"{path}: valve_controller.holding_registers.fire_command: missing: {why} starts the "
                          f"pulse by writing valve_controller.fire_command_value ({vc.fire_command_value}) there")
    if style == FireStyle.HOST_TIMED_COIL and not vc.host_timed_fire_allowed:
        raise ConfigError(f"{path}: valve_controller.host_timed_fire_allowed: {why} has this computer open and "
                          "close the fire valve; if it stops mid-pulse the valve stays open until the controller's "
                          f"link watchdog closes it ({vc.watchdog_s:g} s): set host_timed_fire_allowed = true only "
                          "if the lab accepts that, else use a style the PLC times")
    if vc.host_timed_fire_allowed and style != FireStyle.HOST_TIMED_COIL:
        raise ConfigError(f"{path}: valve_controller.host_timed_fire_allowed: only for fire_style = "
                          f'"host_timed_coil" (this rig fires with "{style}")')


def check_plausibility(config: RigConfig, path: Path) -> None:
    """Every pressure the limits allow must be a plausible reading."""
    _, high = config.plausibility.reservoir_range_bar(config.limits)
    if high <= config.limits.max_pressure_bar:
        raise ConfigError(f"{path}: plausibility.reservoir_max_bar: {high:g} bar must be above "
                          f"limits.max_pressure_bar ({config.limits.max_pressure_bar:g} bar): an overpressure "
                          "must read as one, not as nonsense")
    if config.plausibility.vacuum_max_mbar <= config.limits.fixture_vacuum_max_mbar:
        raise ConfigError(f"{path}: plausibility.vacuum_max_mbar: must be above limits.fixture_vacuum_max_mbar")


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
    if amp.driver in ("serial-bridge", "manual") and amp.options:
        raise ConfigError(f"{path}: amplifier.options: only for a lab's own driver (driver = \"package.module:Class\")")


def _check_driver(driver: str, built_in: tuple[str, ...], path: Path, section: str) -> None:
    """A lab's driver class must import and have its role's methods (rig/driver_classes.py)."""
    if driver not in built_in:
        from hopkinson.rig.driver_classes import driver_class

        driver_class(driver, section, f"{path}: {section}.driver")


def check_register_map(register_map: RegisterMap, path: Path, prefix: str) -> None:
    overlaps = register_map.overlaps()
    if overlaps:
        raise ConfigError(f"{path}: {prefix}: {overlaps[0]}")
