"""The one physics model behind the simulated rig (docs/bar-physics.md; docs/decisions/0004).

`World` is one object whose single lock guards the whole physical state (pneumatics,
controller, amplifier, the pending shot); every method below takes it. What a shot puts on the
channels is drivers/sim/shot_signals.py, its truth drivers/sim/shot_truth.py, and the
configuration ([world] of sim.toml) drivers/sim/world_params.py.

The Modbus controller, the SCPI digitizer and the serial amplifier of the simulated rig all
read and change this one World, so a fired shot gives consistent pressures, trigger and
waveforms.

Time. The world keeps simulated time, `time_scale` times the wall clock (monotonic), and
advances lazily: every access first integrates the state from the last access to now, in
closed form per step (linear fill ramp, exponential vent/exhaust/pump-down, linear leak), so
the result does not depend on how often it is polled. Tests may pass their own `clock`.

Pneumatics. Pressures are gauge bar (0 = ambient). The fill valve feeds the reservoir at
`fill_rate_bar_s` from a supply at `supply_pressure_bar`; the controller regulates: while the
fill coil is on, the fill valve closes itself at the set-point (fault `stuck-fill-valve`: the
valve, once open, stays open whatever it is told, and the pressure climbs to the supply).
The vent valve and an open fire valve let the reservoir decay exponentially to ambient. The
fixture vacuum (absolute mbar) falls exponentially to `pump_floor_mbar` while the pump runs
and leaks back towards atmosphere at `leak_rate_mbar_s` when it stops (fault `vacuum-leak`:
the pump cannot get below `fault_leak_floor_mbar`).

Shot. Opening the fire valve (a rising edge of the fire coil) with at least
`min_fire_pressure_bar` in the reservoir launches the projectile: speed = k·√p; the
calibrated object's velocity change Δv = `velocity_transfer`·speed; a half-sine acceleration
pulse of the projectile's width δ (No. 3: 38.6 µs; wider for No. 1 and 2) and peak
π·Δv/(2δ); then the object flies off at constant speed. With [world.realism] enabled
(`RealismParams`, drivers/sim/real_records.py) the pulse comes from the world's pulse source
(`WorldParams.pulse_source`: the closed form above or the bar model) with a shot-to-shot scatter
of the speed, and the records carry the effects of a real rig, every one recorded in the shot's
truth. The hardware interlock chain of the controller keeps the fire valve shut while the door
is open or the e-stop is tripped. If the digitizer is armed at that moment, the next
`capture(settings)` returns the channels around the digitizer's own trigger (a real crossing of
its level, with its slope, on its source; none, and the shot passes unrecorded; `CHANNELS`,
`WorldParams.channels()`). The truth of the last shot is kept in `last_shot_truth`; every callable in
`launch_listeners` is called with it at each launch (a witness such as a fire log).

Controller. Like a real PLC, the controller keeps a link watchdog and times the fire pulse:

- heartbeat writes (`heartbeat(value)`): 1 starts a session (clears a trip, arms the watchdog),
  2..65535 are beats, 0 disarms. With the watchdog armed and no write for `watchdog_s` of
  *wall-clock* time (the link's time, not the simulated physics' time), the controller trips:
  fill and fire de-energised, pump stopped, vent opened; it stays "tripped" (and refuses to
  energise fill, fire or pump) until a new session starts. The trip is applied at the exact
  moment it fell due, however late the world is next looked at.
- `fire_pulse(duration_s)`: the controller opens the fire valve for `duration_s` of simulated
  time and closes it itself; refused (the reason returned) when the e-stop, the door or a
  tripped watchdog forbids it; every pulse that opened the valve is counted.
- `valve_positions()`: the valves as they really are (a stuck fill valve is open whatever its
  coil says), beside `coils()`, what they were told.

Amplifier. Gain, excitation, low-pass, auto-zero (removes the bridge offset), shunt
calibration (adds the output of a known equivalent acceleration) and an overload latch (set
when the output passes `output_limit_v`, cleared by `clear_amp_overload` or auto-zero; fault
`amp-overload` forces it on).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.shock import velocity_m_s
from hopkinson.drivers.sim.shot_signals import response_rate_hz, shot_channels
from hopkinson.drivers.sim.shot_truth import FiredShot, reference_dict, truth_dict
from hopkinson.drivers.sim.world_params import (
    CHANNELS,
    PROJECTILES,
    AccelerometerParams,
    AmplifierParams,
    LauncherParams,
    PneumaticsParams,
    SecondSensorParams,
    SignalParams,
    WorldParams,
)

__all__ = ["CHANNELS", "PROJECTILES", "AccelerometerParams", "AmplifierParams", "CaptureSettings", "LauncherParams",
           "PneumaticsParams", "SecondSensorParams", "SignalParams", "World", "WorldParams", "simulate_shot"]


@dataclass
class AmplifierState:
    """The bridge amplifier's current settings and status (guarded by the world's lock)."""

    gain: float
    excitation_v: float
    lowpass_hz: float
    shunt_on: bool = False
    overload_latched: bool = False
    bridge_offset_v: float = 0.0


class World:
    """The simulated rig's physics; thread-safe, advanced lazily from `clock`."""

    def __init__(
        self,
        params: WorldParams | None = None,
        faults: FaultSet | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.params = params or WorldParams()
        self.faults = faults if faults is not None else FaultSet()
        self._clock = clock
        self._lock = threading.RLock()
        p = self.params.pneumatics
        self._t0_wall = clock()
        self._sim_s = 0.0
        self._pressure_bar = 0.0
        self._vacuum_mbar = p.atmosphere_mbar
        self._setpoint_bar = 0.0
        self._coils = {"fire": False, "fill": False, "vent": False, "pump": False}
        self._fill_open = False  # the fill valve's physical state
        self._watchdog_s = p.watchdog_s
        self._watchdog = "off"  # "off" | "armed" | "tripped"
        self._last_beat_wall = 0.0
        self.watchdog_trips = 0
        self.watchdog_tripped_at_sim_s: float | None = None
        self._pulse_end_s: float | None = None  # simulated time the running fire pulse ends
        self.fire_pulses = 0
        self._inputs = {"door": p.door_closed, "clamped": p.fixture_clamped, "estop": p.estop_healthy}
        self._projectile = self.params.launcher.projectile
        self._pulse_source = self.params.pulse_source()
        a = self.params.amplifier
        self.amplifier = AmplifierState(a.gain, a.excitation_v, a.lowpass_hz,
                                        bridge_offset_v=self.params.accelerometer.bridge_offset_v)
        self.shots_fired = 0
        self.fire_refusals: list[str] = []
        self.last_shot_truth: dict[str, Any] | None = None
        self._pending: FiredShot | None = None
        # Set by the simulated rig: is the digitizer armed right now? None = always armed.
        self.digitizer_armed: Callable[[], bool] | None = None
        # Called once per launch with a copy of that shot's `last_shot_truth` (taken before any
        # capture adds to it), in the thread that opened the fire valve, after the world's lock
        # is released and before set_fire_valve returns (so before the Modbus reply goes back).
        self.launch_listeners: list[Callable[[dict[str, Any]], None]] = []

    # -- time -----------------------------------------------------------------------------
    def sim_time_s(self) -> float:
        """Simulated seconds since the world started (advances the state)."""
        with self._lock:
            self._advance()
            return self._sim_s

    def _advance(self) -> None:
        now = (self._clock() - self._t0_wall) * self.params.time_scale
        while True:  # controller events that fall due before now happen at their own time
            due_s, event = self._next_event()
            if event is None or due_s > now:
                break
            self._integrate_to(due_s)
            event()
        self._integrate_to(now)

    def _next_event(self) -> tuple[float, Callable[[], None] | None]:
        events: list[tuple[float, Callable[[], None]]] = []
        if self._pulse_end_s is not None:
            events.append((self._pulse_end_s, self._end_pulse))
        if self._watchdog == "armed":
            due_wall = self._last_beat_wall + self._watchdog_s
            events.append(((due_wall - self._t0_wall) * self.params.time_scale, self._trip_watchdog))
        return min(events, key=lambda e: e[0]) if events else (math.inf, None)

    def _integrate_to(self, until_s: float) -> None:
        dt = until_s - self._sim_s
        if dt <= 0:
            return
        # Steps of at most 50 ms simulated: each step is exact for its constant regime; the
        # step only matters where the regime changes (the set-point is reached).
        steps = max(1, min(100_000, math.ceil(dt / 0.05)))
        h = dt / steps
        for _ in range(steps):
            self._step(h)
        self._sim_s = until_s

    def _step(self, h: float) -> None:
        p = self.params.pneumatics
        # Fill valve physics: the controller closes it at the set-point unless it is stuck.
        stuck = self.faults.active("stuck-fill-valve") and self._fill_open
        if not stuck:
            self._fill_open = self._coils["fill"] and self._pressure_bar < self._setpoint_bar
        target = p.supply_pressure_bar if stuck else min(self._setpoint_bar, p.supply_pressure_bar)
        rate = p.fill_rate_bar_s if self._fill_open else 0.0
        inverse_tau = 0.0
        if self._coils["vent"]:
            inverse_tau += 1.0 / p.vent_time_constant_s
        if self._coils["fire"]:
            inverse_tau += 1.0 / p.fire_exhaust_time_constant_s
        if inverse_tau > 0:
            equilibrium = rate / inverse_tau
            self._pressure_bar = equilibrium + (self._pressure_bar - equilibrium) * math.exp(-h * inverse_tau)
        else:
            self._pressure_bar += rate * h
        if self._fill_open and self._pressure_bar > target:  # the step crossed the set-point
            self._pressure_bar = target
        self._pressure_bar = max(self._pressure_bar, 0.0)
        # Vacuum fixture.
        floor = p.pump_floor_mbar
        if self.faults.active("vacuum-leak"):
            floor = max(floor, p.fault_leak_floor_mbar)
        if self._coils["pump"]:
            self._vacuum_mbar = floor + (self._vacuum_mbar - floor) * math.exp(-h / p.pump_time_constant_s)
            if self._vacuum_mbar < floor:  # the leak fault struck with a good vacuum
                self._vacuum_mbar = min(floor, self._vacuum_mbar + 100.0 * p.leak_rate_mbar_s * h)
        else:
            leak = p.leak_rate_mbar_s * (100.0 if self.faults.active("vacuum-leak") else 1.0)
            self._vacuum_mbar = min(p.atmosphere_mbar, self._vacuum_mbar + leak * h)

    # -- controller side ------------------------------------------------------------------
    def coils(self) -> dict[str, bool]:
        """Commanded actuator states: fire, fill, vent, pump."""
        with self._lock:
            self._advance()
            return dict(self._coils)

    def valve_positions(self) -> dict[str, bool]:
        """The valves as they really are (True = open): fire, fill, vent."""
        with self._lock:
            self._advance()
            return {"fire": self._coils["fire"], "fill": self._fill_open, "vent": self._coils["vent"]}

    def _energise_refusal(self) -> str:
        return "link watchdog tripped" if self._watchdog == "tripped" else ""

    def set_fill_valve(self, open_: bool) -> str:
        """Command the fill valve; returns the controller's refusal ("" = done)."""
        with self._lock:
            self._advance()
            if open_ and (refusal := self._energise_refusal()):
                return refusal
            self._coils["fill"] = bool(open_)
            if open_ and self._pressure_bar < self._setpoint_bar:
                self._fill_open = True
            elif not open_ and not self.faults.active("stuck-fill-valve"):
                self._fill_open = False
            return ""

    def set_vent_valve(self, open_: bool) -> str:
        with self._lock:
            self._advance()
            self._coils["vent"] = bool(open_)
            return ""

    def set_pump(self, on: bool) -> str:
        with self._lock:
            self._advance()
            if on and (refusal := self._energise_refusal()):
                return refusal
            self._coils["pump"] = bool(on)
            return ""

    def set_pressure_setpoint_bar(self, pressure_bar: float) -> None:
        with self._lock:
            self._advance()
            self._setpoint_bar = max(0.0, float(pressure_bar))

    def pressure_setpoint_bar(self) -> float:
        with self._lock:
            return self._setpoint_bar

    def load_projectile(self, projectile: int) -> None:
        """The projectile type now in the barrel (1..3)."""
        if projectile not in PROJECTILES:
            raise ValueError(f"projectile must be one of {PROJECTILES}, got {projectile}")
        with self._lock:
            self._projectile = projectile

    def projectile(self) -> int:
        with self._lock:
            return self._projectile

    def set_fire_valve(self, open_: bool) -> str:
        """Command the fire valve; a rising edge with pressure in the reservoir fires a shot.
        Returns the refusal ("" = done): the interlock chain keeps the valve (and its coil) shut."""
        return self._operate_fire(open_, None)

    def fire_pulse(self, duration_s: float) -> str:
        """Open the fire valve for `duration_s` simulated seconds, closed by the controller.
        Returns the refusal ("" = fired)."""
        if not 0 < duration_s < math.inf:
            raise ValueError(f"fire pulse must be positive, got {duration_s!r}")
        return self._operate_fire(True, duration_s)

    def _operate_fire(self, open_: bool, pulse_s: float | None) -> str:
        # Ask the digitizer before taking our lock: its server calls capture() under its own.
        armed = True if self.digitizer_armed is None else bool(self.digitizer_armed())
        launched: dict[str, Any] | None = None
        with self._lock:
            self._advance()
            was_open = self._coils["fire"]
            if open_ and not was_open:
                refusal = self._fire_refusal()
                if refusal:
                    self.fire_refusals.append(refusal)
                    return refusal  # the valve stays shut; the coil reads back shut
                self._coils["fire"] = True
                if pulse_s is not None:
                    self._pulse_end_s = self._sim_s + pulse_s
                    self.fire_pulses += 1
                if self._pressure_bar >= self.params.pneumatics.min_fire_pressure_bar:
                    launched = dict(self._launch(armed))
            elif open_ and pulse_s is not None:
                return "the fire valve is already open"
            elif not open_:
                self._coils["fire"] = False
                self._pulse_end_s = None
        if launched is not None:
            for listener in list(self.launch_listeners):  # outside the lock: a listener may be slow
                listener(launched)
        return ""

    def _end_pulse(self) -> None:
        self._coils["fire"] = False
        self._pulse_end_s = None

    def _fire_refusal(self) -> str:
        if not self.estop_healthy():
            return "e-stop tripped"
        if not self.door_closed():
            return "door open"
        return self._energise_refusal()

    # -- link watchdog ----------------------------------------------------------------------
    def heartbeat(self, value: int) -> None:
        """A write to the heartbeat register (module docstring: 0 stop, 1 start, else a beat)."""
        with self._lock:
            self._advance()  # a trip that fell due before this write happens first
            self._last_beat_wall = self._clock()
            if value == 0:
                if self._watchdog == "armed":
                    self._watchdog = "off"
            elif value == 1:
                self._watchdog = "armed"
            elif self._watchdog == "off":
                self._watchdog = "armed"  # a beat without a session start arms it too

    def set_watchdog_s(self, seconds: float) -> None:
        """The watchdog time the host asks for."""
        if not 0 < seconds <= 3600:
            raise ValueError(f"watchdog time must be in (0, 3600] s, got {seconds!r}")
        with self._lock:
            self._advance()
            self._watchdog_s = float(seconds)

    def watchdog_s(self) -> float:
        with self._lock:
            return self._watchdog_s

    def watchdog_state(self) -> str:
        """"off", "armed" or "tripped"."""
        with self._lock:
            self._advance()
            return self._watchdog

    def _trip_watchdog(self) -> None:
        """The heartbeat fell silent: de-energise fill and fire, stop the pump, vent."""
        self._watchdog = "tripped"
        self.watchdog_trips += 1
        self.watchdog_tripped_at_sim_s = self._sim_s
        self._coils.update(fire=False, fill=False, pump=False, vent=True)
        self._pulse_end_s = None
        if not self.faults.active("stuck-fill-valve"):
            self._fill_open = False

    def reservoir_pressure_bar(self) -> float:
        with self._lock:
            self._advance()
            return self._pressure_bar

    def fixture_vacuum_mbar(self) -> float:
        with self._lock:
            self._advance()
            return self._vacuum_mbar

    def door_closed(self) -> bool:
        with self._lock:
            return self._inputs["door"] and not self.faults.active("door-open")

    def fixture_clamped(self) -> bool:
        with self._lock:
            return self._inputs["clamped"]

    def estop_healthy(self) -> bool:
        with self._lock:
            return self._inputs["estop"] and not self.faults.active("estop")

    def set_inputs(self, *, door_closed: bool | None = None, fixture_clamped: bool | None = None,
                   estop_healthy: bool | None = None) -> None:
        """Operate the door, the clamp or the e-stop (tests and the panel's sim controls)."""
        with self._lock:
            for key, value in (("door", door_closed), ("clamped", fixture_clamped), ("estop", estop_healthy)):
                if value is not None:
                    self._inputs[key] = bool(value)

    # -- amplifier side -------------------------------------------------------------------
    def amp_settings(self) -> AmplifierState:
        """A copy of the amplifier's state."""
        with self._lock:
            return AmplifierState(**asdict(self.amplifier))

    def set_amp_gain(self, gain: float) -> None:
        with self._lock:
            self.amplifier.gain = float(gain)

    def set_amp_excitation_v(self, excitation_v: float) -> None:
        with self._lock:
            self.amplifier.excitation_v = float(excitation_v)

    def set_amp_lowpass_hz(self, lowpass_hz: float) -> None:
        with self._lock:
            self.amplifier.lowpass_hz = float(lowpass_hz)

    def set_amp_shunt(self, on: bool) -> None:
        with self._lock:
            self.amplifier.shunt_on = bool(on)

    def amp_auto_zero(self) -> None:
        """Balance the bridge: the output offset goes to the residual; clears the overload latch."""
        with self._lock:
            a = self.amplifier
            residual = self.params.amplifier.auto_zero_residual_v
            a.bridge_offset_v = residual / a.gain if a.gain else 0.0
            a.overload_latched = False

    def clear_amp_overload(self) -> None:
        with self._lock:
            self.amplifier.overload_latched = False

    def amp_output_v(self) -> float:
        """DC output of the amplifier (offset, plus the shunt step when shunt cal is on)."""
        with self._lock:
            a = self.amplifier
            out = a.gain * (a.bridge_offset_v + (self._shunt_bridge_v() if a.shunt_on else 0.0))
            limit = self.params.amplifier.output_limit_v
            if abs(out) > limit:
                a.overload_latched = True
            return float(np.clip(out, -limit, limit))

    def amp_overloaded(self) -> bool:
        with self._lock:
            self.amp_output_v()
            return self.amplifier.overload_latched or self.faults.active("amp-overload")

    def _bridge_sensitivity(self) -> float:
        acc = self.params.accelerometer
        return acc.sensitivity_v_per_m_s2 * self.amplifier.excitation_v / acc.nominal_excitation_v

    def _shunt_bridge_v(self) -> float:
        return self._bridge_sensitivity() * self.params.accelerometer.shunt_equivalent_m_s2

    # -- the shot -------------------------------------------------------------------------
    def _launch(self, armed: bool) -> dict[str, Any]:
        """Fire the projectile at the reservoir's pressure; return the shot's truth dict."""
        pressure = self._pressure_bar
        realism = self.params.realism
        factor = 1.0
        if realism.enabled and realism.speed_scatter_rel > 0:  # its own generator: the noise stays as it was
            draw = np.random.default_rng([self.params.seed, self.shots_fired + 1, 5]).standard_normal()
            factor = max(0.5, 1.0 + realism.speed_scatter_rel * float(draw))
        pulse = self._pulse_source.pulse(self._projectile, pressure, factor)
        speed, delta_v, width, peak = pulse.speed_m_s, pulse.delta_v_m_s, pulse.width_s, pulse.peak_m_s2
        a = self.amplifier
        acc = self.params.accelerometer
        modes = tuple(acc.modes)
        sine_modes = None
        if realism.enabled and realism.mount.enabled:  # base compliance: the mounted resonance is higher
            sine_modes = modes
            modes = tuple(Mode(m.natural_frequency_hz * realism.mount.frequency_ratio, m.damping_ratio) for m in modes)
        truth = AccelerometerTruth(
            modes=modes,
            lowpass_hz=a.lowpass_hz,
            lowpass_order=self.params.amplifier.lowpass_order,
            sensitivity=1.0,
            zero_shift=acc.zero_shift_m_s2,
        )
        self.shots_fired += 1
        shunt = self._shunt_bridge_v() if a.shunt_on else 0.0
        shot = FiredShot(
            number=self.shots_fired, fired_at_s=self._sim_s, pressure_bar=pressure,
            projectile=self._projectile, speed_m_s=speed, delta_v_m_s=delta_v, width_s=width,
            peak_m_s2=peak, truth=truth, gain=a.gain, excitation_v=a.excitation_v,
            bridge_sensitivity_v_per_m_s2=self._bridge_sensitivity(),
            output_offset_v=a.gain * (a.bridge_offset_v + shunt),
            truth_2=self.params.accelerometer_2.truth() if self.params.accelerometer_2.enabled else None,
            pulse=pulse, speed_factor=factor, sine_modes=sine_modes,
        )
        shot_truth = self.last_shot_truth = truth_dict(shot, self.params)
        # The static peak output latches the overload even when nobody records the shot;
        # capture() checks the actual waveform (resonance overshoot included).
        peak_out = abs(shot.output_offset_v) + shot.gain * shot.bridge_sensitivity_v_per_m_s2 * peak
        if peak_out > self.params.amplifier.output_limit_v:
            a.overload_latched = True
        self._pending = shot if armed and not self.faults.active("no-trigger") else None
        return shot_truth

    def capture(self, settings: Any) -> dict[int, np.ndarray] | None:
        """The digitizer's view: None until a shot fired while armed, then its channels (by number).

        `settings` has sample_rate_hz, record_length and pre_trigger_samples (the simulated
        digitizer's AcquisitionSettings). Without a `trigger_index` method the pulse starts at
        the trigger index. With one (the simulated digitizer triggers on a real crossing), the
        world serves two records' length with the pulse half a record after the pre-trigger,
        and `settings.trigger_index(channels, first, last)` picks the record around the first
        crossing in first..last, or returns None: then the shot passes unrecorded (truth
        "capture": {"triggered": false}). A shot is delivered once.
        """
        with self._lock:
            if self.faults.active("no-trigger") or self._pending is None:
                return None
            shot, self._pending = self._pending, None
        fs = float(settings.sample_rate_hz)
        n = int(settings.record_length)
        pre = int(settings.pre_trigger_samples)
        locate = getattr(settings, "trigger_index", None)
        lead = n // 2 if callable(locate) else 0  # served before and after: the trigger may fall there
        time_s = (np.arange(n + 2 * lead) - pre - lead) / fs
        channels, velocity, motion = shot_channels(self.params, shot, time_s, fs)
        first = 0
        if callable(locate):
            k = locate(channels, pre, pre + 2 * lead)
            if k is None:
                with self._lock:
                    if self.last_shot_truth is not None and self.last_shot_truth["shot_number"] == shot.number:
                        self.last_shot_truth["capture"] = {"triggered": False}
                return None
            first = k - pre
            time_s, velocity = time_s[first:first + n], velocity[first:first + n]
            channels = {ch: x[first:first + n] for ch, x in channels.items()}
        response = channels[2]
        with self._lock:
            if self.last_shot_truth is not None and self.last_shot_truth["shot_number"] == shot.number:
                self.last_shot_truth["capture"] = {
                    "triggered": True, "sample_rate_hz": fs, "record_length": n, "pre_trigger_samples": pre,
                    "pulse_start_index": pre + lead - first,
                }
                if motion is None:
                    self.last_shot_truth["reference"] = reference_dict(time_s, velocity, shot.pulse.acceleration_m_s2)
                else:
                    self.last_shot_truth["reference"] = reference_dict(
                        time_s, np.interp(time_s, motion.time_s, velocity_m_s(motion.spot_m_s2, 1.0 / response_rate_hz(self.params, fs))),
                        lambda t: np.interp(t, motion.time_s, motion.spot_m_s2))
                    self.last_shot_truth["realism"]["drawn"] = motion.drawn
            if np.any(np.abs(response) >= self.params.amplifier.output_limit_v):
                self.amplifier.overload_latched = True
        return channels



@dataclass(frozen=True)
class CaptureSettings:
    """What a digitizer asks `World.capture` for (the pulse starts `pre_trigger_samples` in)."""

    sample_rate_hz: float = 100e6
    record_length: int = 100_000
    pre_trigger_samples: int = 10_000


def simulate_shot(params: WorldParams, pressure_bar: float, projectile: int = 3,
                  settings: CaptureSettings | None = None, shot_number: int = 1
                  ) -> tuple[dict[int, np.ndarray], dict[str, Any]]:
    """One shot of a world of `params` without any server: charged to `pressure_bar`, the
    amplifier zeroed, fired and captured; the channels (by number) and the shot's truth. Shot
    `shot_number` of the world (its noise is drawn from (seed, shot_number))."""
    clock = [0.0]
    world = World(params, clock=lambda: clock[0])
    world.shots_fired = shot_number - 1
    world.load_projectile(projectile)
    world.set_pressure_setpoint_bar(pressure_bar)
    world.set_fill_valve(True)
    clock[0] += 2.0 * pressure_bar / params.pneumatics.fill_rate_bar_s / params.time_scale + 1.0
    world.set_fill_valve(False)
    world.amp_auto_zero()
    world.set_fire_valve(True)
    channels = world.capture(settings or CaptureSettings())
    assert channels is not None and world.last_shot_truth is not None
    return channels, dict(world.last_shot_truth)
