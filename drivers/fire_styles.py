"""How a PLC fires the gas gun: the fire styles the valve controller driver speaks.

A lab's PLC decides how a shot is started; `[valve_controller] fire_style` in rig.toml names
its way (docs/plc-fire-styles.md has an example of each):

- ``pulse_register``: writing the pulse length (ms) to `holding_registers.fire_pulse_ms`
  starts the pulse; the PLC times it and closes the valve itself.
- ``preset_and_coil``: the pulse length is written to `holding_registers.fire_pulse_ms` (a
  preset: writing it fires nothing), then the fire coil (`coils.fire_command`, else
  `coils.fire_valve`) is switched on: the PLC starts a pulse of the preset and times it.
  The driver switches the coil off again once the pulse is over.
- ``preset_and_command``: as above, but a command word starts the pulse:
  `holding_registers.fire_command` is written `fire_command_value` (then 0 once the pulse
  is over).
- ``plc_preset_coil``: only the fire coil is switched on; the PLC times the pulse from a
  preset of its own (read from `holding_registers.fire_pulse_ms` when mapped, never written).
- ``host_timed_coil``: the fire valve's coil is switched on and, `fire_pulse_s` later, off by
  this computer. Only where the lab says so (`host_timed_fire_allowed = true`) and while the
  heartbeat runs: if this computer stops mid-pulse, the PLC's link watchdog closes the valve
  within `watchdog_s`.
"""

from __future__ import annotations

from enum import StrEnum


class FireStyle(StrEnum):
    """How the PLC is told to fire (module docstring)."""

    PULSE_REGISTER = "pulse_register"
    PRESET_AND_COIL = "preset_and_coil"
    PRESET_AND_COMMAND = "preset_and_command"
    PLC_PRESET_COIL = "plc_preset_coil"
    HOST_TIMED_COIL = "host_timed_coil"

    @property
    def writes_preset(self) -> bool:
        """The host writes the pulse length to `fire_pulse_ms` (and it must be mapped)."""
        return self in (FireStyle.PULSE_REGISTER, FireStyle.PRESET_AND_COIL, FireStyle.PRESET_AND_COMMAND)

    @property
    def uses_fire_coil(self) -> bool:
        """A coil starts the pulse (`coils.fire_command`, else `coils.fire_valve`)."""
        return self in (FireStyle.PRESET_AND_COIL, FireStyle.PLC_PRESET_COIL)

    @property
    def timed_by_plc(self) -> bool:
        return self != FireStyle.HOST_TIMED_COIL


FIRE_STYLES = tuple(style.value for style in FireStyle)
FIRE_STYLE_DOC = "docs/plc-fire-styles.md"


def how_it_fires(style: str, fire_pulse_ms: int, fire_coil: int, fire_command: int, command_value: int) -> str:
    """What the host does to fire in `style`, with the addresses (for a "not fired" message)."""
    s = FireStyle(style)
    preset = f"writes the pulse length to holding register {fire_pulse_ms}"
    if s == FireStyle.PULSE_REGISTER:
        return f"{preset} and expects that write to start the pulse"
    if s == FireStyle.PRESET_AND_COIL:
        return f"{preset} as a preset, then switches on coil {fire_coil} to start it"
    if s == FireStyle.PRESET_AND_COMMAND:
        return f"{preset} as a preset, then writes {command_value} to holding register {fire_command} to start it"
    if s == FireStyle.PLC_PRESET_COIL:
        return f"switches on coil {fire_coil} and expects the PLC to time the pulse from its own preset"
    return f"switches the fire valve's coil {fire_coil} on and off itself"
