"""The instrument roles of the rig, as `typing.Protocol`s, and the values they return.

The sequencer, the panel, `status` and `probe` use an instrument only through its role. A lab
whose hardware differs writes one class that has the role's methods (deriving from
`hopkinson.drivers.base.InstrumentDriver` gives the life cycle, the lock and tracing for free)
and names it in `config/rig.toml`:

    [amplifier]
    driver = "mylab.conditioners:ChargeAmp"     # package.module:Class, or an entry point name
    [amplifier.options]                          # passed to the class as keyword arguments
    port = "/dev/ttyUSB3"

`hopkinson.rig.instruments` imports the class, builds it, and checks it against the role
(`missing_members`), naming what is missing. docs/writing-a-driver.md walks through one.

Three roles:

- `ValveControllerRole`: the gas valve / vacuum controller (the PLC). It owns what the software
  cannot guarantee: a link watchdog (no heartbeat for `watchdog_s` -> fill and fire
  de-energised, pump stopped, reservoir vented; latched until a new heartbeat session) and a
  fire pulse it times itself, with a counter of pulses really fired.
- `DigitizerRole`: the transient recorder (channels named by role in rig.toml).
- `AmplifierRole`: the sensor's signal conditioner: read back over its link, or a manual
  conditioner whose settings the technician enters.

Every method that talks to an instrument raises `hopkinson.drivers.errors.InstrumentError`
(naming the instrument, the command and the reply) when the instrument fails.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    from hopkinson.drivers.base import TraceHook
    from hopkinson.drivers.digitizer_settings import DigitizerSettings
    from hopkinson.drivers.digitizer_waveform import Waveform


# -- values ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ValveStates:
    """The actuators as commanded (coils) and, where the controller has position inputs, as
    they really are (`*_position`: True = open, None = the controller does not report it)."""

    fire_valve: bool
    fill_valve: bool
    vent_valve: bool
    vacuum_pump: bool
    fire_valve_position: bool | None = None
    fill_valve_position: bool | None = None
    vent_valve_position: bool | None = None

    def mismatches(self) -> list[str]:
        """Valves open while commanded shut, in plain language (a stuck valve). The other way
        round is normal: the controller shuts the fill valve at the set-point and ends the
        fire pulse while the commands still say open."""
        return [f"{valve.replace('_', ' ')} commanded shut but open" for valve in ("fire_valve", "fill_valve", "vent_valve")
                if getattr(self, f"{valve}_position") and not getattr(self, valve)]

    def is_open(self, valve: str) -> bool:
        """The valve's real position when reported, else its command ("fire_valve", ...)."""
        position = getattr(self, f"{valve}_position", None)
        return bool(getattr(self, valve) if position is None else position)


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


WATCHDOG_STATES = ("off", "armed", "tripped")


@dataclass(frozen=True)
class ControllerStatus:
    """Everything the controller reports, read in one go (what `status` shows).

    watchdog: "off", "armed", "tripped", or "" when the controller does not report it;
    fire_pulse_count: pulses fired since the controller started (None: not reported).
    """

    reservoir_pressure_bar: float
    pressure_setpoint_bar: float
    fixture_vacuum_mbar: float
    valves: ValveStates
    interlocks: Interlocks
    watchdog: str = ""
    fire_pulse_count: int | None = None


@dataclass(frozen=True)
class AmplifierSettings:
    """The conditioner's settings, as read back from it (source "read back") or as the
    technician entered them for a manual conditioner (source "entered").

    gain: output volts per input volt; excitation_v: bridge excitation (0 = none, e.g. IEPE or
    charge); lowpass_hz: filter corner (0 = off); sensitivity_v_per_m_s2: the sensor
    sensitivity set on the conditioner, where it has one (None otherwise).
    """

    gain: float
    excitation_v: float
    lowpass_hz: float
    source: str = "read back"
    sensitivity_v_per_m_s2: float | None = None
    identity: str = ""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def differences(self, other: AmplifierSettings, rel_tol: float = 1e-6) -> list[str]:
        """What differs from `other` (gain, excitation, low-pass, sensitivity), as text."""
        out = []
        for f in fields(self):
            if f.name in ("source", "identity"):
                continue
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if mine is None or theirs is None:
                continue
            if abs(mine - theirs) > rel_tol * max(abs(mine), abs(theirs), 1e-30):
                out.append(f"{f.name}: {mine:g} here, {theirs:g} there")
        return out


# -- roles ----------------------------------------------------------------------------------------
@runtime_checkable
class Instrument(Protocol):
    """What every instrument has: a name, a link, an identity, a trace hook."""

    name: str
    trace: TraceHook | None

    @property
    def connected(self) -> bool: ...

    def connect(self) -> None:
        """Open the link (InstrumentConnectionError when it cannot)."""

    def close(self) -> None:
        """Close the link; idempotent, never raises."""

    def identity(self) -> str:
        """Vendor, model, serial, firmware (or what the instrument says about itself)."""
        ...

    def __enter__(self) -> Any: ...

    def __exit__(self, *exc: object) -> Any: ...


@runtime_checkable
class ValveControllerRole(Instrument, Protocol):
    """The gas valve / vacuum controller. Pressures gauge bar, vacuum absolute mbar."""

    @property
    def has_projectile_register(self) -> bool:
        """True when the controller is told which projectile is loaded (`set_projectile`)."""
        ...

    @property
    def pressure_resolution_bar(self) -> float:
        """The reservoir gauge's resolution (one count), bar; 0 for a float gauge."""
        ...

    def set_fire_valve(self, open_: bool) -> None:
        """Open or close the fire valve (prefer `fire_pulse`: the controller times it)."""

    def set_fill_valve(self, open_: bool) -> None:
        """Open (the controller fills up to the set-point) or close the fill valve."""

    def set_vent_valve(self, open_: bool) -> None:
        """Open (vent to ambient) or close the vent valve."""

    def set_vacuum_pump(self, on: bool) -> None:
        """Start or stop the fixture vacuum pump."""

    def valves(self) -> ValveStates:
        """Commanded coils and, where mapped, the valves' real positions."""
        ...

    def set_pressure_setpoint_bar(self, pressure_bar: float) -> None:
        """Reservoir set-point (ValueError when the register cannot hold it)."""

    def pressure_setpoint_bar(self) -> float: ...

    def set_projectile(self, projectile: int) -> None:
        """Projectile type loaded (1..3); InstrumentError without a projectile register."""

    def reservoir_pressure_bar(self) -> float: ...

    def fixture_vacuum_mbar(self) -> float: ...

    def interlocks(self) -> Interlocks: ...

    def status(self) -> ControllerStatus: ...

    def start_heartbeat(self) -> None:
        """Start a heartbeat session: clears a tripped watchdog, arms it, and keeps it fed
        from a driver thread until `stop_heartbeat` (a read-only client never calls this)."""

    def stop_heartbeat(self) -> None:
        """Stop feeding and disarm the watchdog (a tripped state stays latched)."""

    def watchdog_tripped(self) -> bool:
        """True when the controller's watchdog lapsed since the current session started."""
        ...

    def fire_pulse(self, duration_s: float) -> bool | None:
        """Have the controller open the fire valve for `duration_s` and close it itself (in the
        PLC's fire style, docs/plc-fire-styles.md); InstrumentError when its interlock chain
        refuses. Returns True when the valve was read back open during the pulse, False when it
        read back shut throughout, None when it cannot tell (then the pulse counter or the
        digitizer's trigger confirms the shot)."""

    def fire_pulse_count(self) -> int:
        """Pulses the controller really fired (read before and after to confirm a shot). A driver
        whose controller has no counter says so with `has_pulse_counter = False` (optional)."""
        ...


@runtime_checkable
class AmplifierRole(Instrument, Protocol):
    """The sensor's signal conditioner."""

    def configure(self, *, gain: float, excitation_v: float, lowpass_hz: float) -> None:
        """Set (or, for a manual conditioner, check) the settings; InstrumentError when they
        do not hold."""

    def settings(self) -> AmplifierSettings:
        """The settings as the conditioner has them (read back, or as entered)."""
        ...

    def overloaded(self) -> bool:
        """True when the output overloaded since the last clear (False: no overload signal)."""
        ...

    def auto_zero(self) -> None:
        """Balance the bridge / zero the output (a no-op where there is nothing to zero)."""

    def set_shunt(self, on: bool) -> None:
        """Shunt calibration in or out (a no-op where there is none)."""


@runtime_checkable
class DigitizerRole(Instrument, Protocol):
    """The transient recorder (the digitizer driver's module documents the settings)."""

    @property
    def instrument(self) -> str:
        """How errors name the digitizer (the same as `name` for drivers on the base)."""
        ...

    def configure(self, settings: DigitizerSettings | None = None, **changes: Any) -> None:
        """Apply the acquisition settings (and check them by reading back)."""

    def settings(self) -> DigitizerSettings:
        """The acquisition settings read back from the instrument."""
        ...

    def arm_single(self) -> None: ...

    def abort(self) -> None: ...

    def acquisition_state(self) -> str:
        """"IDLE", "ARMED" or "TRIGGERED"."""
        ...

    def wait_for_trigger(self, timeout_s: float) -> bool: ...

    def fetch_waveform(self, channel: str | int) -> Waveform:
        """One channel's record (by role name, e.g. "response", or channel)."""
        ...


ROLES: dict[str, type] = {
    "valve_controller": ValveControllerRole,
    "digitizer": DigitizerRole,
    "amplifier": AmplifierRole,
}


def role_members(role: type) -> list[str]:
    """The attribute names a class must have to play `role` (methods and properties)."""
    names: set[str] = set()
    for cls in role.__mro__:
        if cls in (object, Protocol) or cls.__name__ in ("Generic",):
            continue
        names.update(getattr(cls, "__annotations__", {}))
        names.update(n for n, v in vars(cls).items() if not n.startswith("_") and (callable(v) or isinstance(v, property)))
    names.update(("__enter__", "__exit__"))
    return sorted(names)


def missing_members(obj: Any, role: type) -> list[str]:
    """The role's members `obj` lacks (empty when it plays the role)."""
    cls = type(obj)
    return [name for name in role_members(role)
            if not (hasattr(cls, name) or name in getattr(obj, "__dict__", {}))]
