"""The shot sequencer: an explicit state machine with a transition table.

    CHECK → EVACUATE → CHARGE → ARM → FIRE → CAPTURE → SAFE → STORE → ANALYSE → DONE
      any error, abort, timeout or interrupt in CHECK..CAPTURE ──► SAFE ──► (STORE) ──► ABORTED
      SAFE not confirmed, or the shot file not written ──────────────────────────────► FAULT

States and what they do (every state has a timeout from [timeouts] in the rig config):

- CHECK: read identities; close the fire and fill valves; configure the amplifier (read back),
  auto-zero it; configure the digitizer; set the projectile register when the controller has
  one; door, clamp, e-stop and amplifier must be healthy.
- EVACUATE: vacuum pump on until the fixture vacuum is at or below limits.fixture_vacuum_max_mbar.
- CHARGE: vent closed, set-point, fill open until the reservoir is within the tolerance of the
  set-point, fill closed. Interlocks watched (incl. vacuum and overpressure).
- ARM: arm the digitizer (the driver checks the instrument's error queue: acknowledged), see it
  ARMED, every interlock holds; then wait for the fire confirmation (FireAuthorisation) while
  watching the interlocks, for `ShotRequest.confirm_timeout_s` (default timeouts.arm_s). A
  "progress" event with data {"awaiting_confirmation": True} tells the panel to ask.
- FIRE: confirmation still given and every interlock holds (read again), then the fire valve is
  pulsed: opened, read back (the controller's own interlock chain may refuse), closed after
  FIRE_PULSE_S. The "state" event of FIRE is published before the valve opens.
- CAPTURE: wait for the digitizer's trigger, fetch both channels (int16 + scaling; one retry on
  a fresh VISA session), note an amplifier overload, take the simulated truth (simulation).
  An abort asked for after the fire command does not stop CAPTURE (still bounded by
  timeouts.capture_s): the projectile is on its way, and its record is worth keeping.
- SAFE (on every path out): fire closed, fill closed, vent open, pump off, digitizer disarmed
  when nothing was captured; then the coils are read back (and re-commanded while wrong) until
  they are right and the reservoir is at or below limits.vent_done_bar, within timeouts.safe_s.
  After a Modbus timeout the controller may still carry out a request it did not answer in
  time, so SAFE then holds and re-checks the coils for SAFE_HOLD (see `_safe_hold_s`). If SAFE
  cannot confirm the safe state, the shot ends in FAULT: the operator must check the rig.
- STORE: whenever data was captured (also after an abort or a fault following the capture):
  the raw shot file written atomically (rig/shot.py, rig/shotfile.py).
- ANALYSE: the analysis in a worker thread, bounded by timeouts.analyse_s; its result or its
  failure stored in the shot file. An analysis failure ends DONE with analysis_error set.

Interrupts. `abort(reason)` may be called from any thread; the running state stops at its next
check (every poll, ≤ ~50 ms plus at most one instrument timeout) and SAFE runs. A
KeyboardInterrupt (or SystemExit) raised in the sequencer's thread is treated the same way and
re-raised only after SAFE (and STORE, when there is data) have run; one arriving during SAFE or
STORE is held until they are done. Abort requests during SAFE and STORE are ignored (that is
where the shot is going anyway); during ANALYSE they abandon the analysis (the shot is kept).

No printing: progress goes to the EventBus (rig/events.py).
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

from hopkinson.drivers.errors import InstrumentError, InstrumentTimeout
from hopkinson.rig.config import RigConfig
from hopkinson.rig.events import EventBus
from hopkinson.rig.instruments import Instruments
from hopkinson.rig.interlocks import REQUIRED, InterlockReport, evaluate, read_readings
from hopkinson.rig.shot import (
    EXIT_ABORTED,
    EXIT_DONE,
    AnalyseFn,
    AnalysisResult,
    CapturedShot,
    ShotOutcome,
    ShotRequest,
    analyse_raw,
    analysis_error_text,
    analysis_params,
    record_analysis,
    shot_meta,
    store_raw_shot,
)

_log = logging.getLogger(__name__)

FIRE_PULSE_S = 0.2  # how long the fire valve stays open (wall seconds); the launch is its rising edge
POLL_INTERVAL_S = 0.05  # watch loops: one read of the interlocks per poll
READINGS_INTERVAL_S = 0.1  # "reading" events at most 10 Hz
PROGRESS_INTERVAL_S = 0.5  # "progress" events of evacuation/charging at most 2 Hz
# Interlocks judged for display while the rig is made or kept safe (SAFE, STORE, ANALYSE).
DISPLAY_INTERLOCKS = ("door", "clamp", "estop", "vacuum", "pressure")


class State(StrEnum):
    """The sequencer's states (their values are the names used in events and messages)."""

    IDLE = "IDLE"
    CHECK = "CHECK"
    EVACUATE = "EVACUATE"
    CHARGE = "CHARGE"
    ARM = "ARM"
    FIRE = "FIRE"
    CAPTURE = "CAPTURE"
    SAFE = "SAFE"
    STORE = "STORE"
    ANALYSE = "ANALYSE"
    DONE = "DONE"
    ABORTED = "ABORTED"
    FAULT = "FAULT"


_S = State
TRANSITIONS: dict[State, frozenset[State]] = {
    _S.IDLE: frozenset({_S.CHECK}),
    _S.CHECK: frozenset({_S.EVACUATE, _S.SAFE}),
    _S.EVACUATE: frozenset({_S.CHARGE, _S.SAFE}),
    _S.CHARGE: frozenset({_S.ARM, _S.SAFE}),
    _S.ARM: frozenset({_S.FIRE, _S.SAFE}),
    _S.FIRE: frozenset({_S.CAPTURE, _S.SAFE}),
    _S.CAPTURE: frozenset({_S.SAFE}),
    _S.SAFE: frozenset({_S.STORE, _S.ABORTED, _S.FAULT}),
    _S.STORE: frozenset({_S.ANALYSE, _S.ABORTED, _S.FAULT}),
    _S.ANALYSE: frozenset({_S.DONE}),
    _S.DONE: frozenset({_S.CHECK}),
    _S.ABORTED: frozenset({_S.CHECK}),
    _S.FAULT: frozenset({_S.CHECK}),
}
FINAL_STATES = frozenset({_S.DONE, _S.ABORTED, _S.FAULT})

# What each state does, for the "state" events.
STATE_TEXT: dict[State, str] = {
    _S.CHECK: "checking instruments and interlocks",
    _S.EVACUATE: "evacuating the fixture",
    _S.CHARGE: "charging the reservoir",
    _S.ARM: "arming the digitizer",
    _S.FIRE: "firing",
    _S.CAPTURE: "waiting for the trigger and fetching the record",
    _S.SAFE: "making the rig safe (fire and fill closed, reservoir vented)",
    _S.STORE: "storing the raw shot",
    _S.ANALYSE: "analysing the shot",
    _S.DONE: "shot done",
    _S.ABORTED: "shot aborted; the rig is safe",
    _S.FAULT: "FAULT: the rig may not be safe, check it",
}


def state_timeout_s(config: RigConfig, state: State) -> float | None:
    """The configured timeout of `state` (None for IDLE and the final states)."""
    name = f"{state.value.lower()}_s"
    return getattr(config.timeouts, name, None)


class FireAuthorisation:
    """The confirmation that the shot may be fired; thread-safe.

    The panel calls give() when the operator confirms (withdraw() takes it back while the
    sequencer waits in ARM); `pre_given()` is for `--yes` and a campaign's authorisation.
    """

    def __init__(self) -> None:
        self._event = threading.Event()

    @classmethod
    def pre_given(cls) -> FireAuthorisation:
        authorisation = cls()
        authorisation.give()
        return authorisation

    def give(self) -> None:
        self._event.set()

    def withdraw(self) -> None:
        self._event.clear()

    @property
    def given(self) -> bool:
        return self._event.is_set()


class _Abort(Exception):
    """Stop the shot: `source` is the instrument (or "operator", "sequencer") and `reason` why."""

    def __init__(self, source: str, reason: str) -> None:
        super().__init__(f"{source}: {reason}")
        self.source = source
        self.reason = reason


@dataclass
class _Failure:
    state: State
    detail: str  # "<instrument>: <why>"


@dataclass
class _Shot:
    """Everything one run of the sequencer learns on the way."""

    request: ShotRequest
    authorisation: FireAuthorisation
    setpoint_bar: float | None = None
    fired: bool = False
    captured: CapturedShot | None = None
    identities: dict[str, str] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    controller_timed_out: bool = False
    interrupt: BaseException | None = None


class Sequencer:
    """Runs shots on connected instruments; see the module docstring.

    instruments: the three connected drivers (rig/instruments.py); used only by the thread in
    run_shot while a shot runs. bus: where events go. analyse: the analysis computation
    (default: rig.shot.analyse_raw); tests may pass another.
    """

    def __init__(
        self,
        instruments: Instruments,
        config: RigConfig,
        bus: EventBus,
        *,
        analyse: AnalyseFn | None = None,
        poll_interval_s: float = POLL_INTERVAL_S,
        fire_pulse_s: float = FIRE_PULSE_S,
    ) -> None:
        self.instruments = instruments
        self.config = config
        self.bus = bus
        self._analyse = analyse or analyse_raw
        self._poll_s = poll_interval_s
        self._fire_pulse_s = fire_pulse_s
        self._lock = threading.Lock()
        self._run_lock = threading.Lock()
        self._state = State.IDLE
        self._abort_event = threading.Event()
        self._abort_reason = ""
        self._deadline = 0.0
        self._timeout_s: float | None = None
        self._last_report: InterlockReport | None = None
        self._last_reading_t = -1e9
        self._last_reading_state = State.IDLE
        self._last_progress_t = -1e9

    # -- public -------------------------------------------------------------------------------
    @property
    def state(self) -> State:
        return self._state

    @property
    def interlocks_ok(self) -> bool:
        """Did every interlock required by the last watch hold? (False before any reading.)"""
        report = self._last_report
        return report is not None and report.all_ok

    @property
    def last_interlocks(self) -> InterlockReport | None:
        return self._last_report

    def abort(self, reason: str = "abort requested") -> None:
        """Ask the running shot to stop and go SAFE (any thread; idempotent; no-op when idle).

        Only sets a flag: the sequencer's own thread notices it within a poll and publishes the
        "error" event, so no subscriber is ever called from the aborting thread.
        """
        with self._lock:
            if self._abort_event.is_set() or self._state in FINAL_STATES or self._state == State.IDLE:
                return
            self._abort_reason = reason
            self._abort_event.set()

    def run_shot(self, request: ShotRequest, authorisation: FireAuthorisation) -> ShotOutcome:
        """Run one shot to its end (blocking). ShotRequestError for a request that cannot be
        fired (nothing done); otherwise a ShotOutcome, SAFE having run on every path."""
        request.check(self.config)
        if not self._run_lock.acquire(blocking=False):
            raise RuntimeError("a shot is already running on this sequencer")
        try:
            with self._lock:
                self._abort_event.clear()
                self._abort_reason = ""
            shot = _Shot(request, authorisation)
            outcome = self._run(shot)
        finally:
            self._run_lock.release()
        if shot.interrupt is not None:
            raise shot.interrupt
        return outcome

    def make_safe(self) -> tuple[bool, str | None]:
        """With no shot running, do SAFE's work and confirm it (blocking; the caller's thread
        must be the one that owns the instruments): fire and fill closed, vent open, pump off,
        digitizer disarmed, coils read back (re-commanded while wrong) until right and the
        reservoir at or below limits.vent_done_bar, within timeouts.safe_s.

        Returns (confirmed, problem). The state does not change; SAFE's "reading", "log" and
        "error" events are published. RuntimeError while a shot runs: abort() it instead.
        """
        if not self._run_lock.acquire(blocking=False):
            raise RuntimeError("a shot is running on this sequencer: abort() it and its SAFE runs")
        try:
            # SAFE keeps its bookkeeping (held interrupt, controller timeouts) on a _Shot; an
            # idle make-safe has no request of its own, hence this placeholder.
            shot = _Shot(ShotRequest(pressure_bar=0.0), FireAuthorisation())
            confirmed = self._safe(shot)
        finally:
            self._run_lock.release()
        if shot.interrupt is not None:
            raise shot.interrupt
        return confirmed

    # -- the run ------------------------------------------------------------------------------
    def _run(self, shot: _Shot) -> ShotOutcome:
        failure: _Failure | None = None
        steps: tuple[tuple[State, Callable[[_Shot], None]], ...] = (
            (State.CHECK, self._check),
            (State.EVACUATE, self._evacuate),
            (State.CHARGE, self._charge),
            (State.ARM, self._arm),
            (State.FIRE, self._fire),
            (State.CAPTURE, self._capture),
        )
        try:
            for state, step in steps:
                self._enter(state)
                step(shot)
        except _Abort as exc:
            failure = _Failure(self._state, f"{exc.source}: {exc.reason}")
        except InstrumentError as exc:
            if isinstance(exc, InstrumentTimeout) and exc.instrument == self.instruments.valves.name:
                shot.controller_timed_out = True
            failure = _Failure(self._state, str(exc))
        except Exception as exc:  # a bug or an unexpected library error: still make the rig safe
            _log.exception("unexpected error in %s", self._state)
            failure = _Failure(self._state, f"sequencer: unexpected error: {type(exc).__name__}: {exc}")
        except BaseException as exc:  # KeyboardInterrupt, SystemExit: deferred until SAFE has run
            shot.interrupt = exc
            failure = _Failure(self._state, f"operator: interrupted ({type(exc).__name__})")
        if failure is not None:
            self._shielded(shot, lambda: self.bus.emit("error", failure.state, f"aborting: {failure.detail}"))

        self._shielded(shot, lambda: self._enter(State.SAFE))
        safe_ok, safe_problem = self._safe(shot)

        path: Path | None = None
        store_error: str | None = None
        if shot.captured is not None:
            path, store_error = self._store(shot)

        results: dict[str, Any] | None = None
        analysis_error: str | None = None
        if failure is None and safe_ok and store_error is None and path is not None:
            results, analysis_error = self._analyse_and_record(shot, path)
            final = State.DONE
        elif safe_ok and store_error is None:
            final = State.ABORTED
        else:
            final = State.FAULT

        error = self._message(shot, failure, safe_ok, safe_problem, path, store_error)
        aborted_in = failure.state.value if failure is not None else (
            State.SAFE.value if not safe_ok else State.STORE.value if store_error else None)
        outcome = ShotOutcome(
            final_state=final.value,
            shot_path=path if store_error is None else None,
            results=results,
            error=error,
            exit_code=EXIT_DONE if final == State.DONE else EXIT_ABORTED,
            aborted_in=aborted_in,
            fired=shot.fired,
            analysis_error=analysis_error,
            safe_confirmed=safe_ok,
            warnings=tuple(shot.warnings),
        )
        self._shielded(shot, lambda: self._enter(final))
        self._shielded(shot, lambda: self.bus.emit(
            "result", final, error or analysis_error or STATE_TEXT[final],
            shot_path=str(outcome.shot_path) if outcome.shot_path else None, results=results,
            error=error or analysis_error, analysis_error=analysis_error, final_state=final.value,
            exit_code=outcome.exit_code, fired=shot.fired, aborted_in=aborted_in,
            safe_confirmed=safe_ok, warnings=list(shot.warnings)))
        return outcome

    def _message(self, shot: _Shot, failure: _Failure | None, safe_ok: bool, safe_problem: str | None,
                 path: Path | None, store_error: str | None) -> str | None:
        """The one-line error: which state, which instrument, why; what became of the rig and data."""
        if failure is None and safe_ok and store_error is None:
            return None
        parts = []
        if failure is not None:
            parts.append(f"shot aborted in {failure.state.value}: {failure.detail}")
        if safe_ok:
            if failure is not None:
                parts.append("rig safe (fire and fill valves closed, reservoir vented)")
        else:
            parts.append(f"SAFE NOT CONFIRMED: {safe_problem}; check the rig by hand")
        if store_error is not None:
            parts.append(f"STORE failed: {store_error}")
        elif path is not None:
            parts.append(f"the recorded data is kept in {path}")
        elif shot.fired:
            parts.append("the shot was fired but nothing was recorded")
        return "; ".join(parts)

    # -- state plumbing -----------------------------------------------------------------------
    def _enter(self, state: State) -> None:
        with self._lock:
            if state not in TRANSITIONS[self._state]:
                raise RuntimeError(f"illegal sequencer transition {self._state.value} -> {state.value}")
            self._state = state
        self._timeout_s = state_timeout_s(self.config, state)
        self._deadline = time.monotonic() + (self._timeout_s if self._timeout_s is not None else 0.0)
        self.bus.emit("state", state, STATE_TEXT.get(state, state.value), timeout_s=self._timeout_s)

    def _checkpoint(self, source: str, waiting_for: str, honour_abort: bool = True) -> None:
        """Raise _Abort when an abort was asked for (if honoured) or the state's time is up."""
        if honour_abort and self._abort_event.is_set():
            raise _Abort("operator", f"aborted: {self._abort_reason}")
        if self._timeout_s is not None and time.monotonic() > self._deadline:
            raise _Abort(source, f"timed out after {self._timeout_s:g} s {waiting_for}")

    def _pause(self, source: str, waiting_for: str) -> None:
        """Wait one poll interval (woken early by an abort), then check."""
        self._abort_event.wait(self._poll_s)
        self._checkpoint(source, waiting_for)

    def _shielded(self, shot: _Shot, action: Callable[[], Any]) -> Any:
        """Run `action`; an Exception is logged, an interrupt is held for after SAFE/STORE."""
        try:
            return action()
        except Exception:
            _log.exception("in %s", self._state)
        except BaseException as exc:
            if shot.interrupt is None:
                shot.interrupt = exc
        return None

    def _source(self, interlock: str) -> str:
        if interlock == "digitizer":
            return self.instruments.digitizer.instrument
        if interlock == "amplifier":
            return self.instruments.amplifier.name
        return self.instruments.valves.name

    def _watch(self, shot: _Shot, state: State, *, charging: bool = False, digitizer: bool = False,
               required: tuple[str, ...] | None = None) -> InterlockReport:
        """Read and judge the interlocks of `state`; publish a reading; abort if one is lost."""
        names = required if required is not None else REQUIRED[state.value]
        readings = read_readings(self.instruments, amplifier="amplifier" in names, digitizer=digitizer)
        report = evaluate(readings, self.config.limits, names, shot.setpoint_bar, charging)
        self._last_report = report
        self._publish_reading(report)
        if not report.all_ok:
            first = report.failing()[0]
            raise _Abort(self._source(first), f"interlock lost: {'; '.join(report.problems())}")
        return report

    def _publish_reading(self, report: InterlockReport) -> None:
        """A "reading" event: the first of each state, then at most every READINGS_INTERVAL_S."""
        now = time.monotonic()
        if self._state != self._last_reading_state or now - self._last_reading_t >= READINGS_INTERVAL_S:
            self._last_reading_t, self._last_reading_state = now, self._state
            self.bus.emit("reading", self._state, "readings", **report.event_data())

    def _progress(self, message: str, force: bool = False, **data: Any) -> None:
        now = time.monotonic()
        if force or now - self._last_progress_t >= PROGRESS_INTERVAL_S:
            self._last_progress_t = now
            self.bus.emit("progress", self._state, message, **data)

    # -- CHECK .. CAPTURE -----------------------------------------------------------------------
    def _check(self, shot: _Shot) -> None:
        inst, cfg = self.instruments, self.config
        if not inst.digitizer.connected:  # a session closed by an earlier failure: start afresh
            inst.digitizer.connect()
        shot.identities = inst.identities()
        inst.valves.set_fire_valve(False)
        inst.valves.set_fill_valve(False)
        self._checkpoint(inst.valves.name, "closing the valves")
        amp = cfg.amplifier
        inst.amplifier.configure(gain=amp.gain, excitation_v=amp.excitation_v, lowpass_hz=amp.lowpass_hz)
        inst.amplifier.set_shunt(False)
        inst.amplifier.auto_zero()
        shot.settings["amplifier_gain"] = inst.amplifier.gain()
        shot.settings["amplifier_excitation_v"] = amp.excitation_v
        shot.settings["amplifier_lowpass_hz"] = amp.lowpass_hz
        self._checkpoint(inst.amplifier.name, "configuring the amplifier")
        d = cfg.digitizer
        inst.digitizer.abort()
        inst.digitizer.configure(sample_rate_hz=d.sample_rate_hz, record_length=d.record_length,
                                 pre_trigger_fraction=d.pre_trigger_fraction, ch1_range_v=d.ch1_range_v,
                                 ch2_range_v=d.ch2_range_v, trigger_source=d.trigger_source,
                                 trigger_level_v=d.trigger_level_v, trigger_slope=d.trigger_slope)
        self._checkpoint(inst.digitizer.instrument, "configuring the digitizer")
        projectile = shot.request.projectile
        if cfg.valve_controller.holding_registers.projectile >= 0:
            inst.valves.set_projectile(projectile)
        else:
            self.bus.emit("log", State.CHECK, f"the controller has no projectile register: make sure "
                                              f"projectile No. {projectile} is loaded")
        self._watch(shot, State.CHECK)
        self._checkpoint(inst.valves.name, "checking the interlocks")

    def _evacuate(self, shot: _Shot) -> None:
        valves, limit = self.instruments.valves, self.config.limits.fixture_vacuum_max_mbar
        valves.set_vacuum_pump(True)
        while True:
            report = self._watch(shot, State.EVACUATE)
            vacuum = report.readings.fixture_vacuum_mbar
            if vacuum <= limit:
                self._progress(f"fixture vacuum {vacuum:.1f} mbar", force=True, fixture_vacuum_mbar=vacuum)
                return
            self._progress(f"evacuating: {vacuum:.1f} mbar, needs {limit:g} mbar", fixture_vacuum_mbar=vacuum)
            self._pause(valves.name, f"waiting for the fixture vacuum ({vacuum:.1f} mbar, needs {limit:g} mbar)")

    def _charge(self, shot: _Shot) -> None:
        valves, limits = self.instruments.valves, self.config.limits
        target = float(shot.request.pressure_bar)
        valves.set_vent_valve(False)
        valves.set_pressure_setpoint_bar(target)
        shot.setpoint_bar = target
        valves.set_fill_valve(True)
        while True:
            report = self._watch(shot, State.CHARGE, charging=True)
            p = report.readings.reservoir_pressure_bar
            if p >= target - limits.pressure_tolerance_bar:
                break
            self._progress(f"charging: {p:.3f} of {target:g} bar", reservoir_pressure_bar=p, target_bar=target)
            self._pause(valves.name, f"charging the reservoir ({p:.3f} of {target:g} bar)")
        valves.set_fill_valve(False)
        self._progress(f"charged: {p:.3f} bar", force=True, reservoir_pressure_bar=p, target_bar=target)

    def _arm(self, shot: _Shot) -> None:
        dig = self.instruments.digitizer
        dig.arm_single()
        self._watch(shot, State.ARM, digitizer=True)
        self._checkpoint(dig.instrument, "arming")
        if shot.authorisation.given:
            return
        wait_s = shot.request.confirm_timeout_s
        if wait_s is None:
            wait_s = self.config.timeouts.arm_s
        self._timeout_s, self._deadline = None, time.monotonic() + wait_s  # the wait has its own limit
        self.bus.emit("progress", State.ARM, "armed: waiting for the fire confirmation",
                      awaiting_confirmation=True, timeout_s=wait_s)
        while not shot.authorisation.given:
            if time.monotonic() >= self._deadline:
                raise _Abort("operator", f"shot not confirmed (no fire confirmation within {wait_s:g} s: "
                                         "give --yes, the panel's confirmation or a campaign authorisation)")
            self._abort_event.wait(self._poll_s)
            self._checkpoint("operator", "waiting for the fire confirmation")
            self._watch(shot, State.ARM, digitizer=True)
        self.bus.emit("progress", State.ARM, "fire confirmed", awaiting_confirmation=False)

    def _fire(self, shot: _Shot) -> None:
        valves = self.instruments.valves
        if not shot.authorisation.given:
            raise _Abort("operator", "fire confirmation withdrawn")
        report = self._watch(shot, State.FIRE, digitizer=True)
        self._checkpoint(valves.name, "before firing")
        shot.settings["pressure_at_fire_bar"] = report.readings.reservoir_pressure_bar
        shot.settings["fixture_vacuum_at_fire_mbar"] = report.readings.fixture_vacuum_mbar
        shot.fired = True  # from here on the projectile may be on its way
        valves.set_fire_valve(True)
        if not valves.valves().fire_valve:
            shot.fired = False
            raise _Abort(valves.name, "the fire valve did not open (refused by the controller's interlock chain)")
        self.bus.emit("progress", State.FIRE, "fired", reservoir_pressure_bar=report.readings.reservoir_pressure_bar)
        self._abort_event.wait(self._fire_pulse_s)
        valves.set_fire_valve(False)

    def _capture(self, shot: _Shot) -> None:
        dig = self.instruments.digitizer
        while True:
            state = dig.acquisition_state()
            if state == "TRIGGERED":
                break
            if state != "ARMED":
                raise _Abort(dig.instrument, f"the digitizer left the armed state before a trigger (state {state})")
            time.sleep(min(self._poll_s, 0.01))
            self._checkpoint(dig.instrument, "waiting for the trigger (the shot was fired; nothing recorded)",
                             honour_abort=False)
        doppler, response = self._fetch(1), self._fetch(2)
        self._checkpoint(dig.instrument, "fetching the record", honour_abort=False)
        try:
            if self.instruments.amplifier.overloaded():
                message = "the amplifier overloaded during the shot: the response may be clipped"
                shot.warnings.append(message)
                self.bus.emit("log", State.CAPTURE, message, level="warning")
        except InstrumentError as exc:
            shot.warnings.append(f"amplifier overload status not read after the shot: {exc}")
        truth = None
        if self.instruments.simulated_truth is not None:
            raw_truth = self.instruments.simulated_truth()
            truth = json.loads(json.dumps(raw_truth)) if raw_truth is not None else None
        shot.settings["amplifier_overloaded"] = any("overloaded" in w for w in shot.warnings)
        shot.captured = CapturedShot(doppler, response, dict(shot.settings), truth)
        self.bus.emit("progress", State.CAPTURE, f"captured {doppler.codes.size} samples per channel",
                      samples=int(doppler.codes.size), sample_rate_hz=doppler.sample_rate_hz)

    def _fetch(self, channel: int) -> Any:
        """One channel's waveform; one retry on a fresh session (the record stays in the digitizer)."""
        dig = self.instruments.digitizer
        try:
            return dig.fetch_waveform(channel)
        except InstrumentError as exc:
            self.bus.emit("log", State.CAPTURE, f"fetching channel {channel} failed, retrying once: {exc}",
                          level="warning")
            self._checkpoint(dig.instrument, "fetching the record", honour_abort=False)
            dig.connect()
            return dig.fetch_waveform(channel)

    # -- SAFE, STORE, ANALYSE ---------------------------------------------------------------------
    def _safe_hold_s(self) -> float:
        """How long SAFE keeps re-checking the coils after a Modbus timeout: a request the
        controller did not answer in time may still be carried out later (seen with a slow
        controller), e.g. a late "fill open" after SAFE closed it."""
        return min(max(1.0, 4.0 * self.config.valve_controller.timeout_s), self.config.timeouts.safe_s / 2)

    def _safe(self, shot: _Shot) -> tuple[bool, str | None]:
        """Make the rig safe and confirm it (never raises); returns (confirmed, problem)."""
        inst, limits = self.instruments, self.config.limits
        valves = inst.valves
        start = time.monotonic()
        deadline = start + self.config.timeouts.safe_s
        wanted = {"fire_valve": False, "fill_valve": False, "vent_valve": True, "vacuum_pump": False}
        setters = {"fire_valve": valves.set_fire_valve, "fill_valve": valves.set_fill_valve,
                   "vent_valve": valves.set_vent_valve, "vacuum_pump": valves.set_vacuum_pump}
        problem: str | None = None
        errors = 0  # instrument errors so far: a round without a new one can confirm

        def attempt(action: Callable[[], Any]) -> Any:
            nonlocal problem, errors
            try:
                return action()
            except InstrumentError as exc:
                problem, errors = str(exc), errors + 1
                if isinstance(exc, InstrumentTimeout) and exc.instrument == valves.name:
                    shot.controller_timed_out = True
            except Exception as exc:  # keep going: every other step may still work
                problem, errors = f"sequencer: unexpected error: {type(exc).__name__}: {exc}", errors + 1
                _log.exception("in SAFE")
            except BaseException as exc:
                if shot.interrupt is None:
                    shot.interrupt = exc
            return None

        for name in ("fire_valve", "fill_valve", "vent_valve", "vacuum_pump"):  # the fast path first
            attempt(lambda name=name: setters[name](wanted[name]))
        if shot.captured is None:
            attempt(self._disarm_digitizer)

        confirmed = False
        readings = None
        while True:
            errors_before = errors
            coils = attempt(valves.valves)
            wrong = [n for n in wanted if coils is not None and getattr(coils, n) != wanted[n]]
            for name in wrong:  # a coil that is not as commanded (or was changed late): again
                attempt(lambda name=name: setters[name](wanted[name]))
            readings = attempt(lambda: read_readings(inst, amplifier=False))
            if readings is not None:
                report = evaluate(readings, limits, DISPLAY_INTERLOCKS)
                self._shielded(shot, lambda report=report: self._publish_reading(report))
            clean_round = errors == errors_before and coils is not None and readings is not None
            # the gauge reads to the nearest count: the true pressure may be half a count higher
            half_count = 0.5 * self.config.valve_controller.scales.pressure_bar_per_count
            vented = readings is not None and readings.reservoir_pressure_bar + half_count <= limits.vent_done_bar
            now = time.monotonic()
            hold_until = start + (self._safe_hold_s() if shot.controller_timed_out else 0.0)
            if clean_round and not wrong and vented and now >= hold_until:
                confirmed = True
                break
            if now >= deadline:
                if clean_round and wrong:
                    problem = f"{valves.name}: coils not as commanded after {self.config.timeouts.safe_s:g} s: {wrong}"
                elif clean_round and not vented:
                    problem = (f"{valves.name}: reservoir still at {readings.reservoir_pressure_bar:.3f} bar "
                               f"after venting for {self.config.timeouts.safe_s:g} s (needs at most "
                               f"{limits.vent_done_bar:g} bar; fill valve stuck open?)")
                break
            try:
                time.sleep(self._poll_s)
            except BaseException as exc:  # an interrupt while we sleep: hold it, carry on
                if shot.interrupt is None:
                    shot.interrupt = exc
        if confirmed:
            assert readings is not None
            p = readings.reservoir_pressure_bar
            self._shielded(shot, lambda: self.bus.emit(
                "log", State.SAFE, f"rig safe: fire and fill closed, vent open, reservoir {p:.3f} bar"))
            return True, None
        self._shielded(shot, lambda: self.bus.emit("error", State.SAFE, f"SAFE NOT CONFIRMED: {problem}"))
        return False, problem

    def _disarm_digitizer(self) -> None:
        dig = self.instruments.digitizer
        if dig.connected:
            dig.abort()

    def _in_worker(self, shot: _Shot, work: Callable[[], Any], timeout_s: float, abandon_on_abort: bool,
                   name: str) -> tuple[bool, Any, BaseException | None]:
        """Run `work` in a daemon thread, publishing readings while waiting.

        Returns (finished, value, exception). Not finished: the timeout passed, or an abort/
        interrupt came and `abandon_on_abort`; the thread is then left to end on its own (a
        Python thread cannot be stopped) and its result is ignored.
        """
        if abandon_on_abort and (self._abort_event.is_set() or shot.interrupt is not None):
            return False, None, None  # asked to stop before it began: do not start it
        box: dict[str, Any] = {}

        def target() -> None:
            try:
                box["value"] = work()
            except BaseException as exc:  # handed to the sequencer's thread
                box["error"] = exc

        thread = threading.Thread(target=target, name=f"sequencer-{name}", daemon=True)
        thread.start()
        deadline = time.monotonic() + timeout_s
        readings_ok = True
        while True:
            try:
                thread.join(self._poll_s)
            except BaseException as exc:
                if shot.interrupt is None:
                    shot.interrupt = exc
            if not thread.is_alive():
                return True, box.get("value"), box.get("error")
            if time.monotonic() >= deadline:
                return False, None, None
            if abandon_on_abort and (self._abort_event.is_set() or shot.interrupt is not None):
                return False, None, None
            if readings_ok:  # the rig is safe: readings are for the display only
                try:
                    report = evaluate(read_readings(self.instruments, amplifier=False), self.config.limits,
                                      DISPLAY_INTERLOCKS)
                    self._publish_reading(report)
                except Exception:
                    readings_ok = False

    def _store(self, shot: _Shot) -> tuple[Path | None, str | None]:
        """STORE the raw shot; returns (path, error)."""
        self._shielded(shot, lambda: self._enter(State.STORE))
        assert shot.captured is not None
        request = shot.request
        path = request.shot_path()
        meta = shot_meta(request, self.config, shot.identities, shot.captured)
        captured = shot.captured
        finished, _, error = self._in_worker(shot, lambda: store_raw_shot(path, captured, meta),
                                             self.config.timeouts.store_s, abandon_on_abort=False, name="store")
        if not finished:
            message = (f"{path}: not written within {self.config.timeouts.store_s:g} s "
                       "(the file may still appear)")
        elif error is not None:
            message = f"{path}: {error}"
        else:
            self._shielded(shot, lambda: self.bus.emit("progress", State.STORE, f"raw shot stored in {path}",
                                                       shot_path=str(path)))
            return path, None
        self._shielded(shot, lambda: self.bus.emit("error", State.STORE, f"STORE failed: {message}"))
        return path, message

    def _analyse_and_record(self, shot: _Shot, path: Path) -> tuple[dict[str, Any] | None, str | None]:
        """ANALYSE; the result (or the failure) is stored in the shot file. Never raises."""
        self._shielded(shot, lambda: self._enter(State.ANALYSE))
        assert shot.captured is not None
        captured = shot.captured
        params = analysis_params(shot.request, self.config, shot.settings)
        timeout_s = self.config.timeouts.analyse_s
        finished, value, exc = self._in_worker(
            shot, lambda: self._analyse(captured.raw_shot(), params), timeout_s, abandon_on_abort=True,
            name="analyse")
        result: AnalysisResult | None = None
        if not finished:
            if self._abort_event.is_set() or shot.interrupt is not None:
                error = f"analysis abandoned: {self._abort_reason or 'interrupted'} (re-analyse the stored shot)"
            else:
                error = f"analysis did not finish within {timeout_s:g} s (re-analyse the stored shot)"
        elif exc is not None:
            error = analysis_error_text(exc)
        elif not isinstance(value, AnalysisResult):
            error = f"analysis failed: the analysis returned {type(value).__name__}, not an AnalysisResult"
        else:
            result, error = value, None
        try:
            record_analysis(path, result, error)
        except Exception as store_exc:
            error = f"{error + '; ' if error else ''}the analysis could not be stored in {path}: {store_exc}"
            result = None
        if error is not None:
            self._shielded(shot, lambda: self.bus.emit("log", State.ANALYSE, error, level="warning"))
        return (result.results if result is not None else None), error
