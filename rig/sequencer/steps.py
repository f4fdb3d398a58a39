"""The steps of a shot, CHECK to CAPTURE: each a function of the shot's context.

- CHECK: a held abort stops here before anything moves; identities; fire and fill closed; every
  reading it relies on must be able to be true (rig/plausibility.py: reservoir, vacuum,
  set-point, pulse count; the count must not move during CHECK), else the shot is refused
  naming the value, its register and the likely cause, before any venting; a
  tripped link watchdog gets a new heartbeat session; pressure left in the reservoir is vented
  first (and said so); the amplifier configured (read back) and zeroed; the digitizer
  configured; the projectile set where the controller has a register; door, clamp, e-stop and
  amplifier must hold.
- EVACUATE: vacuum pump on until the fixture vacuum is at or below limits.fixture_vacuum_max_mbar.
- CHARGE: vent closed, set-point, fill open until the reservoir is within the tolerance of the
  set-point, fill closed. Interlocks watched (incl. vacuum and overpressure).
- ARM: the digitizer armed and seen ARMED, every interlock holds; then the fire confirmation
  (FireAuthorisation) is awaited while the interlocks are watched; last, immediately before
  FIRE, the digitizer's, the amplifier's and the controller's settings are read back and
  compared with what this shot needs (another client may have changed them).
- FIRE: confirmation still given, every interlock holds (read again), the `before_fire` hook
  (a campaign journals FIRING), then the controller is told to fire a pulse of
  `valve_controller.fire_pulse_s` in its fire style (docs/plc-fire-styles.md). "Fired" is
  said (the Fired event) only when something confirms it: the pulse counter rising by one,
  the fire valve read back open, or the digitizer's trigger. When the counter stayed or the
  valve read back shut and the digitizer did not trigger: Abort "not fired: the PLC did not
  start the pulse", naming the fire style (nothing was launched). A counter that moves by
  other than one is not trusted (a word-order mistake moves it by 65536).
- CAPTURE: the digitizer's trigger (which confirms a shot nothing else confirmed), then every
  configured channel fetched by role (one retry on
  a fresh session), an amplifier overload noted, the simulated truth taken (simulation). An
  abort asked for after the fire command does not stop CAPTURE (still bounded by
  timeouts.capture_s): the projectile is on its way, and its record is worth keeping.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any

from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.fire_styles import FIRE_STYLE_DOC
from hopkinson.rig.errors import HINT_NOT_CONFIRMED
from hopkinson.rig.events import AwaitingConfirmation, Fired, Identified
from hopkinson.rig.plausibility import (
    PULSE_COUNT,
    RESERVOIR,
    controller_findings,
    counter_moved,
    plausible_ranges,
)
from hopkinson.rig.sequencer.context import Abort, ShotContext
from hopkinson.rig.sequencer.states import State
from hopkinson.rig.shot import CapturedShot, digitizer_channels

HINT_SETTINGS_CHANGED = ("Another program may be using the instrument: close it (hopkinson status only reads), "
                         "then ARM again.")
HINT_NOT_FIRED = "The controller refused the fire pulse: read why above, fix it, then ARM again."
HINT_IMPLAUSIBLE = ("A reading that cannot be true is a mistake in the register map, not a pressure: fix rig.toml, "
                    "check every signal with `hopkinson probe`, then start again.")
HINT_NOT_FIRED_STYLE = (f"Nothing was launched: set valve_controller.fire_style to the way the PLC fires "
                        f"({FIRE_STYLE_DOC}), then fire again.")
PULSE_COUNT_WAIT_S = 1.0  # how long FIRE waits for the controller to count the pulse


def check(ctx: ShotContext) -> None:
    inst, cfg = ctx.instruments, ctx.config
    valves = inst.valves
    ctx.checkpoint(valves.name, "starting the shot")  # an abort held before the shot: nothing moves
    if not inst.digitizer.connected:  # a session closed by an earlier failure: start afresh
        inst.digitizer.connect()
    ctx.identities = inst.identities()
    ctx.events.publish(Identified(state=ctx.state, message="instruments: " + "; ".join(
        f"{k}: {v}" for k, v in ctx.identities.items()), identities=dict(ctx.identities)))
    valves.set_fire_valve(False)
    valves.set_fill_valve(False)
    ctx.checkpoint(valves.name, "closing the valves")
    count_at_check = _check_plausible(ctx)
    _restart_tripped_watchdog(ctx)
    _vent_leftover_pressure(ctx)
    amp = cfg.amplifier
    inst.amplifier.configure(gain=amp.gain, excitation_v=amp.excitation_v, lowpass_hz=amp.lowpass_hz)
    inst.amplifier.set_shunt(False)
    inst.amplifier.auto_zero()
    held = inst.amplifier.settings()  # into the shot file: gain, excitation, low-pass, source ("read back" or
    for key, value in held.to_dict().items():  # "entered"), a hand-set conditioner's sensitivity and identity
        ctx.settings[f"amplifier_{key}"] = float(value) if isinstance(value, int | float) else value
    ctx.checkpoint(inst.amplifier.name, "configuring the amplifier")
    inst.digitizer.abort()
    _configure_digitizer(ctx)
    ctx.checkpoint(inst.digitizer.instrument, "configuring the digitizer")
    projectile = ctx.request.projectile
    if valves.has_projectile_register:
        valves.set_projectile(projectile)
    else:
        ctx.events.note(f"the controller has no projectile register: make sure projectile No. {projectile} is loaded")
    ctx.watch(State.CHECK)
    _check_counter_still(ctx, count_at_check)
    ctx.checkpoint(valves.name, "checking the interlocks")


def _check_plausible(ctx: ShotContext) -> tuple[float, float] | None:
    """Every reading CHECK relies on must be able to be true (rig/plausibility.py), before any
    venting or charging: a word-order or scale mistake is named as such, never taken for a
    pressure to vent. Returns (pulse count, when read) for `_check_counter_still`."""
    valves = ctx.instruments.valves
    readings, findings = controller_findings(valves, ctx.config)
    ctx.untrusted_gauge = next((f for f in findings if f.signal == RESERVOIR), None)
    if findings:
        raise Abort(valves.name, "shot refused: " + "; ".join(f.message for f in findings),
                    " ".join([HINT_IMPLAUSIBLE, *(f"Fix: {f.fix}." for f in findings)]))
    count = readings.get(PULSE_COUNT)
    return (count, time.monotonic()) if count is not None else None


def _check_counter_still(ctx: ShotContext, count_at_check: tuple[float, float] | None) -> None:
    """A pulse counter that moved during CHECK, with nothing fired, is not a pulse counter."""
    if count_at_check is None:
        return
    valves = ctx.instruments.valves
    before, when = count_at_check
    finding = counter_moved(plausible_ranges(ctx.config)[PULSE_COUNT], before, float(valves.fire_pulse_count()),
                            time.monotonic() - when)
    if finding is not None:
        raise Abort(valves.name, f"shot refused: {finding.message}", f"{HINT_IMPLAUSIBLE} Fix: {finding.fix}.")


def _restart_tripped_watchdog(ctx: ShotContext) -> None:
    """A controller whose link watchdog tripped (an earlier session lost its link) refuses to
    energise anything: it has vented already; a new heartbeat session re-arms it."""
    valves = ctx.instruments.valves
    if not getattr(valves, "heartbeat_running", False):
        return  # no heartbeat session in this process (a test rig): nothing to restart
    if valves.watchdog_tripped():
        ctx.warn("the controller's link watchdog had tripped (a heartbeat was missed): it de-energised "
                 "the outputs and vented; starting a new heartbeat session")
        valves.start_heartbeat()


def _vent_leftover_pressure(ctx: ShotContext) -> None:
    """CHECK does not start with pressure in the reservoir: it vents first, and says so.
    Venting may take longer than CHECK itself, so it has timeouts.safe_s."""
    valves, limits = ctx.instruments.valves, ctx.config.limits
    p = _gauge_bar(valves)
    if p <= limits.vent_done_bar:
        return
    ctx.warn(f"the reservoir holds {p:.3f} bar before the shot (above {limits.vent_done_bar:g} bar): "
             "venting it first")
    valves.set_fill_valve(False)
    valves.set_vent_valve(True)
    deadline = time.monotonic() + ctx.config.timeouts.safe_s
    while p > limits.vent_done_bar:
        if time.monotonic() > deadline:
            raise Abort(valves.name, f"the reservoir did not vent below {limits.vent_done_bar:g} bar within "
                                     f"{ctx.config.timeouts.safe_s:g} s (still {p:.3f} bar; fill valve stuck open?)",
                        "Check the fill and vent valves by hand before anything else.")
        ctx.abort.wait(ctx.poll_s)
        if ctx.abort.requested:
            ctx.checkpoint(valves.name, "venting")
        p = _gauge_bar(valves)
    ctx.events.progress(f"vented: {p:.3f} bar", force=True, reservoir_pressure_bar=p)
    ctx.start_clock(State.CHECK)  # CHECK's own time starts after the venting


def _gauge_bar(valves: Any) -> float:
    """The reservoir gauge; Abort when it reads no number (NaN would pass every comparison)."""
    p = valves.reservoir_pressure_bar()
    if not math.isfinite(p):
        raise Abort(valves.name, f"the reservoir gauge reads {p} (not a number): the pressure is unknown",
                    "Check the reservoir gauge and its register; vent the rig by hand if in doubt.")
    return p


def _configure_digitizer(ctx: ShotContext) -> None:
    d = ctx.config.digitizer
    dig = ctx.instruments.digitizer
    wanted = getattr(d, "settings", None)
    if callable(wanted):  # the role's form: the configured DigitizerSettings
        dig.configure(wanted())
        return
    dig.configure(sample_rate_hz=d.sample_rate_hz, record_length=d.record_length,
                  pre_trigger_fraction=d.pre_trigger_fraction, ch1_range_v=d.ch1_range_v,
                  ch2_range_v=d.ch2_range_v, trigger_source=d.trigger_source,
                  trigger_level_v=d.trigger_level_v, trigger_slope=d.trigger_slope)


def evacuate(ctx: ShotContext) -> None:
    valves, limit = ctx.instruments.valves, ctx.config.limits.fixture_vacuum_max_mbar
    valves.set_vacuum_pump(True)
    while True:
        report = ctx.watch(State.EVACUATE)
        vacuum = report.readings.fixture_vacuum_mbar
        if vacuum <= limit:
            ctx.events.progress(f"fixture vacuum {vacuum:.1f} mbar", force=True, fixture_vacuum_mbar=vacuum)
            return
        ctx.events.progress(f"evacuating: {vacuum:.1f} mbar, needs {limit:g} mbar", fixture_vacuum_mbar=vacuum)
        ctx.pause(valves.name, f"waiting for the fixture vacuum ({vacuum:.1f} mbar, needs {limit:g} mbar)")


def charge(ctx: ShotContext) -> None:
    valves, limits = ctx.instruments.valves, ctx.config.limits
    target = float(ctx.request.pressure_bar)
    valves.set_vent_valve(False)
    valves.set_pressure_setpoint_bar(target)
    ctx.setpoint_bar = target
    valves.set_fill_valve(True)
    while True:
        report = ctx.watch(State.CHARGE, charging=True)
        p = report.readings.reservoir_pressure_bar
        if p >= target - limits.pressure_tolerance_bar:
            break
        ctx.events.progress(f"charging: {p:.3f} of {target:g} bar", reservoir_pressure_bar=p, target_bar=target)
        ctx.pause(valves.name, f"charging the reservoir ({p:.3f} of {target:g} bar)")
    valves.set_fill_valve(False)
    ctx.events.progress(f"charged: {p:.3f} bar", force=True, reservoir_pressure_bar=p, target_bar=target)


def arm(ctx: ShotContext) -> None:
    dig = ctx.instruments.digitizer
    dig.arm_single()
    ctx.watch(State.ARM, digitizer=True)
    ctx.checkpoint(dig.instrument, "arming")
    if not ctx.authorisation.given:
        wait_s = ctx.request.confirm_timeout_s
        if wait_s is None:
            wait_s = ctx.config.timeouts.arm_s
        ctx.set_deadline(wait_s)  # the wait has its own limit
        ctx.events.publish(AwaitingConfirmation(state=ctx.state, message="armed: waiting for the fire confirmation",
                                                timeout_s=wait_s))
        while not ctx.authorisation.given:
            if time.monotonic() >= ctx.deadline:
                raise Abort("operator", f"shot not confirmed (no fire confirmation within {wait_s:g} s: "
                                        "give --yes, the panel's confirmation or a campaign authorisation)",
                            HINT_NOT_CONFIRMED)
            ctx.abort.wait(ctx.poll_s)
            ctx.checkpoint("operator", "waiting for the fire confirmation")
            ctx.watch(State.ARM, digitizer=True)
        ctx.events.progress("fire confirmed", force=True)
    compare_settings(ctx)


def compare_settings(ctx: ShotContext) -> None:
    """Read back the digitizer's, the amplifier's and the controller's settings and compare
    them with what this shot needs; Abort (nothing fired) naming every difference."""
    inst, cfg = ctx.instruments, ctx.config
    problems: list[tuple[str, str]] = []
    wanted = getattr(cfg.digitizer, "settings", None)
    read_back = getattr(inst.digitizer, "settings", None)
    if callable(wanted) and callable(read_back):
        problems += [(inst.digitizer.instrument, d) for d in wanted().differences(read_back())]
    amp = inst.amplifier.settings()
    for name, value in (("gain", cfg.amplifier.gain), ("excitation_v", cfg.amplifier.excitation_v),
                        ("lowpass_hz", cfg.amplifier.lowpass_hz)):
        held = float(getattr(amp, name))
        if not math.isclose(held, value, rel_tol=1e-6, abs_tol=1e-9):
            problems.append((inst.amplifier.name, f"{name}: {value:g} configured, {held:g} on the amplifier"))
    if float(amp.gain) != ctx.settings.get("amplifier_gain", float(amp.gain)):
        problems.append((inst.amplifier.name, "gain changed since CHECK"))
    valves = inst.valves
    setpoint = valves.pressure_setpoint_bar()
    resolution = float(getattr(valves, "pressure_resolution_bar", 0.0) or 0.0)
    if ctx.setpoint_bar is not None and abs(setpoint - ctx.setpoint_bar) > max(resolution, 1e-6):
        problems.append((valves.name, f"pressure set-point: {ctx.setpoint_bar:g} bar wanted, {setpoint:g} bar "
                                      "on the controller"))
    if problems:
        source = problems[0][0]
        raise Abort(source, "settings changed before FIRE: " + "; ".join(f"{s}: {p}" for s, p in problems),
                    HINT_SETTINGS_CHANGED)
    ctx.checkpoint(inst.digitizer.instrument, "reading back the settings")


def fire(ctx: ShotContext) -> None:
    valves = ctx.instruments.valves
    if not ctx.authorisation.given:
        raise Abort("operator", "fire confirmation withdrawn", HINT_NOT_CONFIRMED)
    report = ctx.watch(State.FIRE, digitizer=True)
    ctx.checkpoint(valves.name, "before firing")
    ctx.settings["pressure_at_fire_bar"] = report.readings.reservoir_pressure_bar
    ctx.settings["fixture_vacuum_at_fire_mbar"] = report.readings.fixture_vacuum_mbar
    pulse_s = float(ctx.config.valve_controller.fire_pulse_s)
    count_before = valves.fire_pulse_count() if _has_counter(valves) else None
    if ctx.before_fire is not None:
        try:
            ctx.before_fire(ctx)
        except Abort:
            raise
        except Exception as exc:  # never fire what could not be recorded as firing
            raise Abort("sequencer", f"before firing: {exc}; not fired") from exc
    ctx.checkpoint(valves.name, "before firing")
    ctx.fired = True  # from here on the projectile may be on its way
    try:
        seen_open = valves.fire_pulse(pulse_s)
    except InstrumentError:
        ctx.fired = _pulse_count_rose(ctx, count_before) is not False  # unknown counts as fired
        raise
    ctx.settings["fire_pulse_s"] = float(getattr(valves, "last_pulse_s", None) or pulse_s)  # a PLC preset's own
    ctx.settings["fire_style"] = str(getattr(valves, "fire_style", ctx.config.valve_controller.fire_style))
    count = _wait_for_pulse_count(ctx, count_before) if count_before is not None else None
    ctx.pulse_count = count
    jumped = count is not None and count_before is not None and count - count_before != 1
    if jumped:
        ctx.warn(f"the controller's pulse counter went from {count_before} to {count} for one pulse: it cannot be "
                 f"trusted ({counter_jump_cause(count_before, count)}); not taken as confirming the shot")
    if count is not None and not jumped:
        confirm_fired(ctx, f"the controller's pulse counter ({count_before} → {count})")
    elif seen_open:
        confirm_fired(ctx, "the fire valve's read-back")
    elif _digitizer_triggered(ctx):
        confirm_fired(ctx, "the digitizer's trigger")
    else:
        _not_fired_or_unknown(ctx, count_before, count, jumped, seen_open)


def confirm_fired(ctx: ShotContext, witness: str) -> None:
    """The shot is known fired (by `witness`): say so once (the Fired event)."""
    if ctx.fire_confirmed_by is not None:
        return
    ctx.fire_confirmed_by = witness
    pulse_s = float(ctx.settings.get("fire_pulse_s", ctx.config.valve_controller.fire_pulse_s))
    p = float(ctx.settings.get("pressure_at_fire_bar", math.nan))
    timer = "this computer" if ctx.settings.get("fire_style") == "host_timed_coil" else "the controller"
    ctx.events.publish(Fired(state=ctx.state, message=f"fired at {p:.3f} bar (pulse {pulse_s * 1e3:g} ms, timed by "
                                                      f"{timer}; confirmed by {witness})",
                             reservoir_pressure_bar=p, pulse_s=pulse_s, pulse_count=ctx.pulse_count,
                             confirmed_by=witness))


def _not_fired_or_unknown(ctx: ShotContext, count_before: int | None, count: int | None, jumped: bool,
                          seen_open: bool | None) -> None:
    """Nothing confirmed the shot. When the counter stayed or the valve read back shut (and
    nothing else moved): not fired, Abort naming the fire style. Otherwise the trigger decides
    in CAPTURE."""
    valves = ctx.instruments.valves
    evidence = []
    if count_before is not None and count is None:
        evidence.append(f"its pulse count stayed at {count_before}")
    if seen_open is False:
        evidence.append("the fire valve read back shut")
    if evidence and not jumped:
        ctx.fired = False
        raise Abort(valves.name, f"not fired: the PLC did not start the pulse ({', '.join(evidence)}, the digitizer "
                                 f"did not trigger): check the fire style: {_how_it_fires(ctx)}", HINT_NOT_FIRED_STYLE)
    ctx.warn("the fire command was sent but nothing confirms the shot yet (no pulse counter or valve read-back "
             "says so): the digitizer's trigger decides")


def _how_it_fires(ctx: ShotContext) -> str:
    how = getattr(ctx.instruments.valves, "how_it_fires", None)
    if callable(how):
        return str(how())
    return f'valve_controller.fire_style = "{ctx.config.valve_controller.fire_style}" ({FIRE_STYLE_DOC})'


def counter_jump_cause(before: int, after: int) -> str:
    """Why a pulse counter may move by other than one (a word-order mistake moves it by 65536)."""
    step = after - before
    if step and step % 65536 == 0:
        return f"it moved by {step} = {step // 65536} × 65536: its two words are in the wrong order (word_order)"
    if step < 0:
        return "it went back: a counter that was reset, or not a counter (register address or type)"
    return f"it moved by {step}: another program firing, or not a counter (register address or type)"


def _has_counter(valves: Any) -> bool:
    return bool(getattr(valves, "has_pulse_counter", True))


def _digitizer_triggered(ctx: ShotContext) -> bool:
    try:
        return ctx.instruments.digitizer.acquisition_state() == "TRIGGERED"
    except InstrumentError:
        return False


def _pulse_count_rose(ctx: ShotContext, before: int | None) -> bool | None:
    """Did the controller count a pulse since `before`? None when it cannot be read (or has no counter)."""
    if before is None:
        return None
    try:
        return ctx.instruments.valves.fire_pulse_count() > before
    except InstrumentError:
        return None


def _wait_for_pulse_count(ctx: ShotContext, before: int) -> int | None:
    """The controller's pulse count once it passed `before` (None: not within the wait)."""
    valves = ctx.instruments.valves
    deadline = time.monotonic() + PULSE_COUNT_WAIT_S
    while True:
        count = valves.fire_pulse_count()
        if count != before:
            return count
        if time.monotonic() >= deadline:
            return None
        time.sleep(min(ctx.poll_s, 0.01))


def capture(ctx: ShotContext) -> None:
    dig = ctx.instruments.digitizer
    fired = (f"the shot was fired, confirmed by {ctx.fire_confirmed_by}" if ctx.fire_confirmed_by is not None
             else "the fire command was sent but nothing confirms a shot")
    while True:
        state = dig.acquisition_state()
        if state == "TRIGGERED":
            confirm_fired(ctx, "the digitizer's trigger")
            break
        if state != "ARMED":
            raise Abort(dig.instrument, f"the digitizer left the armed state before a trigger (state {state})")
        time.sleep(min(ctx.poll_s, 0.01))
        ctx.checkpoint(dig.instrument, f"waiting for the trigger ({fired}; nothing recorded)", honour_abort=False)
    channels = {role: _fetch(ctx, channel) for role, channel in digitizer_channels(ctx.config).items()}
    ctx.checkpoint(dig.instrument, "fetching the record", honour_abort=False)
    overloaded = False
    try:
        overloaded = bool(ctx.instruments.amplifier.overloaded())
    except InstrumentError as exc:
        ctx.warn(f"amplifier overload status not read after the shot: {exc}")
    if overloaded:
        ctx.warn("the amplifier overloaded during the shot: the response is clipped")
    truth = None
    if ctx.instruments.simulated_truth is not None:
        raw_truth = ctx.instruments.simulated_truth()
        truth = json.loads(json.dumps(raw_truth)) if raw_truth is not None else None
    ctx.settings["amplifier_overloaded"] = overloaded
    ctx.captured = CapturedShot(channels, dict(ctx.settings), truth)
    first = next(iter(channels.values()))
    ctx.events.progress(f"captured {first.codes.size} samples per channel ({', '.join(channels)})", force=True,
                        samples=int(first.codes.size), sample_rate_hz=first.sample_rate_hz)


def _fetch(ctx: ShotContext, channel: Any) -> Any:
    """One channel's waveform; one retry on a fresh session (the record stays in the digitizer)."""
    dig = ctx.instruments.digitizer
    try:
        return dig.fetch_waveform(channel)
    except InstrumentError as exc:
        ctx.events.warn(f"fetching channel {channel} failed, retrying once: {exc}")
        ctx.checkpoint(dig.instrument, "fetching the record", honour_abort=False)
        dig.connect()
        return dig.fetch_waveform(channel)


STEPS = ((State.CHECK, check), (State.EVACUATE, evacuate), (State.CHARGE, charge), (State.ARM, arm),
         (State.FIRE, fire), (State.CAPTURE, capture))
