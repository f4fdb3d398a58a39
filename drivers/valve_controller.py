"""Gas valve / vacuum controller of the Hopkinson bar, over Modbus TCP or RTU (pymodbus).

The controller (a PLC or a remote-I/O box) exposes, at addresses that come from
`config/rig.toml` as a `RegisterMap` (drivers/registers.py):

- coils: fire valve, fill valve, vent valve, vacuum pump (True = open / running);
- discrete inputs: door/guard closed, fixture clamped, e-stop healthy (True = safe) and,
  where the valves have limit switches, their real positions (True = open);
- holding registers: reservoir pressure set-point; projectile type; the link-watchdog
  heartbeat (and its time); the fire-pulse length;
- input registers: reservoir pressure, fixture vacuum, watchdog state, fire-pulse count.

Pressures are gauge bar (0 = ambient); the fixture vacuum is absolute mbar (~1013 = none).

Fill regulation lives in the controller: while the fill coil is on, it fills the reservoir up
to the set-point and holds it there. The rig still watches the pressure and closes the fill.

What the software cannot guarantee, the controller does:

- **Link watchdog.** `start_heartbeat()` writes 1 to the heartbeat register (a new session:
  clears a tripped watchdog and arms it; first the watchdog time, when the map has
  `watchdog_ms`) and then, from a driver thread, beats 2..65535 every `watchdog_s / 4`. When
  the controller hears nothing for `watchdog_s`, it de-energises fill and fire, stops the
  pump and opens the vent, and latches "tripped" until the next session. `stop_heartbeat()`
  writes 0 (disarm). A read-only client (`status`, `probe`) never writes the register.
- **Fire pulse.** `fire_pulse(duration_s)` fires the way the PLC does it, its fire style
  (drivers/fire_styles.py, docs/plc-fire-styles.md): by default it writes the length in ms and
  the controller opens the fire valve, closes it itself and counts the pulse
  (`fire_pulse_count()`). It watches the fire valve through the pulse and returns whether it
  was read back open (True), read back shut throughout (False), or could not be told apart
  from the host's own command (None). The watch ends when the valve was seen open and then
  shut, or, where the controller counts its pulses, once it counted this one (by exactly one)
  and the valve reads shut with the PLC's own fire output off (without a readable output: once
  the pulse's time has passed); else `PULSE_WATCH_MARGIN_S` after the pulse's time. A pulse
  the interlock chain refuses is answered with a Modbus exception: InstrumentError naming why.

Errors name the instrument, the Modbus function and address, and what came back.
"""

from __future__ import annotations

import contextlib
import threading
import time
from typing import Any

from hopkinson.drivers.base import TraceHook
from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.fire_styles import FIRE_STYLE_DOC, FireStyle, how_it_fires
from hopkinson.drivers.modbus_link import ModbusDriver, ModbusRefusal, ModbusTarget
from hopkinson.drivers.registers import (
    ACTUATORS,
    CoilMap,
    DiscreteInputMap,
    HoldingRegisterMap,
    InputRegisterMap,
    Register,
    RegisterMap,
)
from hopkinson.drivers.roles import (
    WATCHDOG_STATES,
    ControllerStatus,
    Interlocks,
    ValveStates,
)

__all__ = [
    "CoilMap", "ControllerStatus", "DiscreteInputMap", "HoldingRegisterMap", "InputRegisterMap",
    "Interlocks", "ModbusTarget", "RegisterMap", "ValveController", "ValveStates",
]

HEARTBEAT_STOP, HEARTBEAT_START, HEARTBEAT_FIRST_BEAT = 0, 1, 2
DEFAULT_WATCHDOG_S = 3.0
_VALVES = ("fire_valve", "fill_valve", "vent_valve")
PULSE_WATCH_MARGIN_S = 0.3  # how long after its end a pulse is still watched for
PULSE_POLL_S = 0.01  # the fire valve's read-back during a pulse


class ValveController(ModbusDriver):
    """Driver of the gas valve / vacuum controller (module docstring).

    Use as a context manager: `with ValveController(ModbusTarget(host=...)) as vc: vc.status()`,
    or `ValveController.tcp(host, port)`. Thread-safe: every transaction holds the driver lock.
    """

    def __init__(
        self,
        target: ModbusTarget,
        *,
        register_map: RegisterMap | None = None,
        timeout_s: float = 1.0,
        retries: int = 0,
        watchdog_s: float = DEFAULT_WATCHDOG_S,
        fire_style: str = FireStyle.PULSE_REGISTER,
        fire_command_value: int = 1,
        host_timed_fire_allowed: bool = False,
        name: str | None = None,
        trace: TraceHook | None = None,
    ) -> None:
        super().__init__(target, timeout_s=timeout_s, retries=retries,
                         name=name or f"valve controller {target.label}", trace=trace)
        if not 0 < watchdog_s <= 3600:
            raise ValueError(f"{self.name}: watchdog_s must be in (0, 3600] s, got {watchdog_s!r}")
        if fire_style not in FireStyle.__members__.values():
            raise ValueError(f"{self.name}: fire_style must be one of {', '.join(FireStyle)}, got {fire_style!r}")
        if not 1 <= fire_command_value <= 0xFFFF:
            raise ValueError(f"{self.name}: fire_command_value must be 1..65535, got {fire_command_value!r}")
        self.map = register_map or RegisterMap()
        self.watchdog_s = float(watchdog_s)
        self.fire_style = FireStyle(fire_style)
        self.fire_command_value = int(fire_command_value)
        self.host_timed_fire_allowed = bool(host_timed_fire_allowed)
        self.last_pulse_s: float | None = None  # the pulse last fired (plc_preset_coil: the PLC's preset)
        # One stop event per heartbeat session: a thread that outlived its stop (its join timed
        # out while it waited for a slow transaction) ends as soon as it looks, and a new
        # session can never revive it.
        self._beat_stop = threading.Event()
        self._beat_thread: threading.Thread | None = None

    @classmethod
    def tcp(cls, host: str, port: int = 502, *, unit_id: int = 1, **kwargs: Any) -> ValveController:
        """A controller on Modbus TCP."""
        return cls(ModbusTarget("tcp", host=host, port=port, unit_id=unit_id), **kwargs)

    def close(self) -> None:
        """Stop the heartbeat (disarming the watchdog, best effort) and close the link."""
        self.stop_heartbeat()
        super().close()

    # -- identity -------------------------------------------------------------------------------
    def identity(self) -> str:
        """Vendor, product code and revision (Modbus 'read device identification', basic)."""
        response = self.call("read device identification", lambda c: c.read_device_information(
            read_code=0x01, object_id=0x00, device_id=self.unit_id))
        info = getattr(response, "information", {}) or {}
        parts = []
        for key in (0x00, 0x01, 0x02):
            value = info.get(key, b"")
            parts.append(value.decode("ascii", "replace") if isinstance(value, bytes) else str(value))
        return ",".join(parts)

    # -- actuators ------------------------------------------------------------------------------
    def set_fire_valve(self, open_: bool) -> None:
        """Open or close the fire valve directly (a shot should use `fire_pulse`). Closing it
        also withdraws a fire command (the fire coil off, the command word 0) where the fire
        style has one."""
        self._write_coil("fire_valve", open_)
        if not open_:
            self._withdraw_fire_command()

    def set_fill_valve(self, open_: bool) -> None:
        """Open the fill valve (the controller fills up to the set-point) or close it."""
        self._write_coil("fill_valve", open_)

    def set_vent_valve(self, open_: bool) -> None:
        """Open (reservoir vents to ambient) or close the vent valve."""
        self._write_coil("vent_valve", open_)

    def set_vacuum_pump(self, on: bool) -> None:
        """Start or stop the fixture vacuum pump."""
        self._write_coil("vacuum_pump", on)

    def valves(self) -> ValveStates:
        """The coils as commanded and, where the map has position inputs, the real positions."""
        c, d = self.map.coils, self.map.discrete_inputs
        coils = self.read_bits("coils", [getattr(c, name) for name in ACTUATORS])
        mapped = {v: getattr(d, f"{v}_open") for v in _VALVES if getattr(d, f"{v}_open") >= 0}
        positions = self.read_bits("discrete inputs", mapped.values()) if mapped else {}
        return ValveStates(
            *(coils[getattr(c, name)] for name in ACTUATORS),
            **{f"{v}_position": positions[a] for v, a in mapped.items()},
        )

    def set_pressure_setpoint_bar(self, pressure_bar: float) -> None:
        """Reservoir pressure set-point (gauge bar); ValueError when the register cannot hold it."""
        self.write_value(self.map.holding_registers.pressure_setpoint, pressure_bar, "pressure set-point", "bar")

    def pressure_setpoint_bar(self) -> float:
        """The set-point as the controller holds it (gauge bar)."""
        return self._read_one("holding registers", "pressure_setpoint", self.map.holding_registers.pressure_setpoint)

    @property
    def has_projectile_register(self) -> bool:
        return self.map.holding_registers.projectile >= 0

    def set_projectile(self, projectile: int) -> None:
        """Tell the controller which projectile type (1..3) is loaded."""
        if projectile not in (1, 2, 3):
            raise ValueError(f"projectile must be 1, 2 or 3, got {projectile}")
        if not self.has_projectile_register:
            raise InstrumentError(self.name, "set projectile", "this controller has no projectile register")
        self.write_word(self.map.holding_registers.projectile, projectile, "projectile")

    # -- gauges and interlocks ------------------------------------------------------------------
    @property
    def pressure_resolution_bar(self) -> float:
        return self.map.input_registers.reservoir_pressure.resolution

    def reservoir_pressure_bar(self) -> float:
        """Reservoir gauge pressure in bar."""
        return self._read_one("input registers", "reservoir_pressure", self.map.input_registers.reservoir_pressure)

    def fixture_vacuum_mbar(self) -> float:
        """Absolute pressure in the vacuum fixture, mbar (lower is a better vacuum)."""
        return self._read_one("input registers", "fixture_vacuum", self.map.input_registers.fixture_vacuum)

    def interlocks(self) -> Interlocks:
        """Door, clamp and e-stop inputs (True = safe)."""
        d = self.map.discrete_inputs
        addresses = (d.door_closed, d.fixture_clamped, d.estop_healthy)
        bits = self.read_bits("discrete inputs", addresses)
        return Interlocks(*(bits[a] for a in addresses))

    def status(self) -> ControllerStatus:
        """Pressures, vacuum, valves, interlocks, watchdog and pulse count (reads only)."""
        i = self.map.input_registers
        gauges = {"reservoir_pressure": i.reservoir_pressure, "fixture_vacuum": i.fixture_vacuum}
        if i.fire_pulse_count.present:
            gauges["fire_pulse_count"] = i.fire_pulse_count
        values = self.read_values("input registers", gauges)
        count = values.get("fire_pulse_count")
        return ControllerStatus(
            reservoir_pressure_bar=values["reservoir_pressure"],
            pressure_setpoint_bar=self.pressure_setpoint_bar(),
            fixture_vacuum_mbar=values["fixture_vacuum"],
            valves=self.valves(),
            interlocks=self.interlocks(),
            watchdog=self.watchdog_state() if i.watchdog_state >= 0 else "",
            fire_pulse_count=None if count is None else int(count),
        )

    # -- link watchdog --------------------------------------------------------------------------
    def start_heartbeat(self) -> None:
        """Start a heartbeat session (module docstring); InstrumentError without a heartbeat register."""
        address = self._required("heartbeat", self.map.holding_registers.heartbeat)
        self.stop_heartbeat_thread()
        watchdog = self.map.holding_registers.watchdog_ms
        if watchdog.present:
            self.write_value(watchdog, self.watchdog_s * 1000.0, "watchdog time", "ms")
        self.write_word(address, HEARTBEAT_START, "heartbeat: start a session")
        self._beat_stop = threading.Event()
        self._beat_thread = threading.Thread(target=self._beat, args=(address, self._beat_stop), daemon=True,
                                             name=f"heartbeat {self.name}")
        self._beat_thread.start()

    def _beat(self, address: int, stop: threading.Event) -> None:
        period_s = max(0.02, self.watchdog_s / 4.0)
        beat = HEARTBEAT_FIRST_BEAT
        while not stop.wait(period_s):
            with contextlib.suppress(InstrumentError):  # keep trying: if the link stays down, the controller trips
                with self.lock:
                    if not stop.is_set():  # stopped while this beat waited for the link: never beat late
                        self.write_word(address, beat, "heartbeat")
            beat = beat + 1 if beat < 0xFFFF else HEARTBEAT_FIRST_BEAT

    def stop_heartbeat_thread(self) -> None:
        """Stop the driver's beats without telling the controller (its watchdog will lapse)."""
        thread, self._beat_thread = self._beat_thread, None
        if thread is not None:
            self._beat_stop.set()
            thread.join(max(1.0, 2 * self.timeout_s * (self.retries + 1)))

    def stop_heartbeat(self) -> None:
        """Stop the beats and disarm the watchdog (0). Never raises: if the disarm cannot be
        written, the watchdog lapses and the controller vents, which is safe. A link that a
        failure closed is reopened for the disarm (a transient error must not leave the
        controller to trip and vent after a good shot)."""
        running = self._beat_thread is not None
        self.stop_heartbeat_thread()
        if running and self._wanted:
            with contextlib.suppress(InstrumentError):
                self.write_word(self.map.holding_registers.heartbeat, HEARTBEAT_STOP, "heartbeat: stop")

    @property
    def heartbeat_running(self) -> bool:
        return self._beat_thread is not None and self._beat_thread.is_alive()

    def watchdog_state(self) -> str:
        """"off", "armed" or "tripped" as the controller reports it."""
        address = self._required("watchdog_state", self.map.input_registers.watchdog_state)
        code = self.read_words("input registers", [address])[address]
        if not 0 <= code < len(WATCHDOG_STATES):
            raise InstrumentError(self.name, f"read input registers {address} (watchdog state)",
                                  "not a watchdog state (0 off, 1 armed, 2 tripped)", str(code))
        return WATCHDOG_STATES[code]

    def watchdog_tripped(self) -> bool:
        """True when the watchdog lapsed since the current heartbeat session started."""
        return self.watchdog_state() == "tripped"

    # -- fire pulse -----------------------------------------------------------------------------
    def fire_pulse(self, duration_s: float) -> bool | None:
        """Fire a pulse of `duration_s` the PLC's way (its fire style, module docstring) and
        watch the fire valve through it. Returns True when the valve was read back open, False
        when it read back shut throughout, None when nothing but the host's own command could
        be read back. InstrumentError when the controller refuses (naming why)."""
        if not 0 < duration_s <= 60:
            raise ValueError(f"{self.name}: fire pulse must be in (0, 60] s, got {duration_s!r}")
        style = self.fire_style
        h = self.map.holding_registers
        if style.writes_preset:
            self._required("fire_pulse_ms", h.fire_pulse_ms.address)
        if style == FireStyle.PRESET_AND_COMMAND:
            self._required("fire_command", h.fire_command)
        if style == FireStyle.HOST_TIMED_COIL and not (self.host_timed_fire_allowed and self.heartbeat_running):
            why = ("the lab has not allowed it (valve_controller.host_timed_fire_allowed)"
                   if not self.host_timed_fire_allowed else "no heartbeat runs, so the watchdog cannot back it")
            raise InstrumentError(self.name, "fire pulse", f"a pulse timed by this computer is refused: {why}")
        if style == FireStyle.PLC_PRESET_COIL and h.fire_pulse_ms.present:
            with contextlib.suppress(InstrumentError):  # the PLC's own preset, when it can be read
                preset_s = self._read_one("holding registers", "fire_pulse_ms", h.fire_pulse_ms) / 1000.0
                if 0 < preset_s <= 60:
                    duration_s = preset_s
        self.last_pulse_s = duration_s
        count_before = self._pulse_count_or_none()
        try:
            if style == FireStyle.PULSE_REGISTER:
                self.write_value(h.fire_pulse_ms, duration_s * 1000.0, "fire pulse", "ms")
            elif style.writes_preset:
                self.write_value(h.fire_pulse_ms, duration_s * 1000.0, "fire pulse preset", "ms")
            started = time.monotonic()
            if style.uses_fire_coil or style == FireStyle.HOST_TIMED_COIL:
                coil = self.map.coils.fire_valve if style == FireStyle.HOST_TIMED_COIL else self.fire_coil
                self.write_coil(coil, True, "fire coil" if coil != self.map.coils.fire_valve else "fire valve")
            elif style == FireStyle.PRESET_AND_COMMAND:
                self.write_word(h.fire_command, self.fire_command_value, "fire command")
        except ModbusRefusal as exc:
            raise InstrumentError(self.name, exc.command, f"fire pulse refused by the controller: {self._why_refused()}",
                                  exc.reply) from exc
        try:
            return self._watch_pulse(started, duration_s, count_before)
        finally:
            if style != FireStyle.PULSE_REGISTER:
                self._end_fire_command()

    @property
    def fire_coil(self) -> int:
        """The coil that starts a pulse in the coil styles: coils.fire_command, else coils.fire_valve."""
        c = self.map.coils
        return c.fire_command if c.fire_command >= 0 else c.fire_valve

    @property
    def has_pulse_counter(self) -> bool:
        return self.map.input_registers.fire_pulse_count.present

    def how_it_fires(self) -> str:
        """What this driver does to fire, with the addresses (for a "not fired" message)."""
        h = self.map.holding_registers
        coil = self.map.coils.fire_valve if self.fire_style == FireStyle.HOST_TIMED_COIL else self.fire_coil
        return (f'fire_style = "{self.fire_style}" ' + how_it_fires(self.fire_style, h.fire_pulse_ms.address, coil,
                                                                 h.fire_command, self.fire_command_value)
                + f" ({FIRE_STYLE_DOC})")

    def _fire_valve_readback(self) -> tuple[str, int] | None:
        """Where the real fire valve can be read: its position input, else its coil when the
        host did not write that coil itself to fire (then it is the PLC's output); None."""
        position = self.map.discrete_inputs.fire_valve_open
        if position >= 0:
            return "discrete inputs", position
        output = self._plc_fire_output()
        return None if output is None else ("coils", output)

    def _plc_fire_output(self) -> int | None:
        """The fire valve's coil when it is the PLC's own output (the host did not write it to
        fire); None when the host writes it."""
        written = (self.map.coils.fire_valve if self.fire_style == FireStyle.HOST_TIMED_COIL
                   else self.fire_coil if self.fire_style.uses_fire_coil else -1)
        return None if written == self.map.coils.fire_valve else self.map.coils.fire_valve

    def _pulse_count_or_none(self) -> int | None:
        """The controller's pulse count, None without a counter or when it cannot be read."""
        if not self.has_pulse_counter:
            return None
        try:
            return self.fire_pulse_count()
        except InstrumentError:
            return None

    def _watch_pulse(self, started: float, duration_s: float, count_before: int | None) -> bool | None:
        """Read the fire valve back until the pulse is over (seen open, then shut; or counted
        and shut, `_pulse_over`) or its time and a margin have passed; a host-timed pulse is
        ended here. A failed read is not a failed shot: the pulse counter and the trigger still
        tell."""
        source = self._fire_valve_readback()
        host_timed = self.fire_style == FireStyle.HOST_TIMED_COIL
        seen_open = False
        ends = started + duration_s
        while True:
            now = time.monotonic()
            if host_timed and now >= ends:
                self._close_host_timed_valve()
                host_timed = False
            if source is not None:
                with contextlib.suppress(InstrumentError):
                    is_open = self.read_bits(source[0], [source[1]])[source[1]]
                    if seen_open and not is_open:
                        break  # open, then shut: the pulse is over
                    if not is_open and not host_timed and self._pulse_over(count_before, source, now >= ends):
                        break  # counted, and shut (a pulse shorter than one read-back)
                    seen_open = seen_open or is_open
            elif not host_timed:
                break  # nothing to watch, nothing to time
            if now >= ends + PULSE_WATCH_MARGIN_S:
                break
            time.sleep(PULSE_POLL_S)
        return seen_open if source is not None else None

    def _pulse_over(self, count_before: int | None, source: tuple[str, int], past_its_time: bool) -> bool:
        """With the fire valve read shut at `source`: is the PLC's pulse over? Yes when its
        counter moved by exactly one since `count_before` (it started this pulse: a counter that
        jumps is not trusted) and its own fire output is off (a valve that has not opened yet
        has its output on); where the output is the host's command, once the pulse's time has
        passed."""
        if count_before is None or self._pulse_count_or_none() != count_before + 1:
            return False
        output = self._plc_fire_output()
        if output is None:
            return past_its_time
        if source == ("coils", output):
            return True  # `source` is that output, read shut
        try:
            return not self.read_bits("coils", [output])[output]
        except InstrumentError:
            return past_its_time

    def _close_host_timed_valve(self) -> None:
        """End a host-timed pulse. When the close cannot be written within a second, the
        heartbeat is stopped so that the controller's watchdog closes the valve (it backs the
        host-timed style), and InstrumentError says so."""
        deadline = time.monotonic() + 1.0
        while True:
            try:
                self.write_coil(self.map.coils.fire_valve, False, "fire valve")
                return
            except InstrumentError as exc:
                if time.monotonic() >= deadline:
                    self.stop_heartbeat_thread()
                    raise InstrumentError(self.name, exc.command, f"the host-timed fire valve could not be closed "
                                          f"({exc.problem}): the heartbeat is stopped, so the controller's watchdog "
                                          f"closes it within {self.watchdog_s:g} s", exc.reply) from exc
                time.sleep(PULSE_POLL_S)

    def _end_fire_command(self) -> None:
        """After a pulse: the fire coil off, or the command word back to 0 (best effort: SAFE
        withdraws it again)."""
        with contextlib.suppress(InstrumentError):
            style = self.fire_style
            if style == FireStyle.HOST_TIMED_COIL or (style.uses_fire_coil and self.fire_coil == self.map.coils.fire_valve):
                self.write_coil(self.map.coils.fire_valve, False, "fire valve")
            self._withdraw_fire_command()

    def _withdraw_fire_command(self) -> None:
        """A fire coil of its own off, or the command word back to 0 (where the style has one)."""
        style = self.fire_style
        if style.uses_fire_coil and self.fire_coil != self.map.coils.fire_valve:
            self.write_coil(self.fire_coil, False, "fire coil")
        elif style == FireStyle.PRESET_AND_COMMAND and self.map.holding_registers.fire_command >= 0:
            self.write_word(self.map.holding_registers.fire_command, 0, "fire command: none")

    def fire_pulse_count(self) -> int:
        """Pulses the controller fired since it started."""
        register = self.map.input_registers.fire_pulse_count
        self._required("fire_pulse_count", register.address)
        return int(self._read_one("input registers", "fire_pulse_count", register))

    def _why_refused(self) -> str:
        """The controller's reason for refusing an output, as far as its inputs tell."""
        reasons: list[str] = []
        with contextlib.suppress(InstrumentError):
            reasons += self.interlocks().problems()
        if self.map.input_registers.watchdog_state >= 0:
            with contextlib.suppress(InstrumentError):
                if self.watchdog_tripped():
                    reasons.append("link watchdog tripped (start a new heartbeat session)")
        return ", ".join(reasons) or "its interlock chain (no input says why)"

    # -- helpers --------------------------------------------------------------------------------
    def _write_coil(self, coil: str, value: bool) -> None:
        try:
            self.write_coil(getattr(self.map.coils, coil), value, coil.replace("_", " "))
        except ModbusRefusal as exc:
            if not value:
                raise
            raise InstrumentError(self.name, exc.command, f"refused by the controller: {self._why_refused()}",
                                  exc.reply) from exc

    def _read_one(self, table: str, name: str, register: Register) -> float:
        return self.read_values(table, {name: register})[name]

    def _required(self, what: str, address: int) -> int:
        if address < 0:
            raise InstrumentError(self.name, what, f"the register map has no {what} register "
                                  f"(valve_controller.*.{what} in rig.toml)")
        return address
