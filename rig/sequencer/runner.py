"""The runner: one shot through the states, SAFE on every way out, then STORE and ANALYSE.

    run_shot: CHECK → EVACUATE → CHARGE → ARM → FIRE → CAPTURE (steps.py)
              → SAFE (safe.py, always) → STORE (when data was captured) → ANALYSE → DONE
              any failure in the steps ──► SAFE ──► (STORE) ──► ABORTED; SAFE or STORE failed ──► FAULT

Interrupts. `abort(reason)` may be called from any thread at any moment, idle or running; it
is held (never needs re-sending) and honoured at the running state's next check (every poll,
≤ ~50 ms plus at most one instrument timeout), or, asked before a shot starts, in that shot's
CHECK before anything moves. A KeyboardInterrupt (or SystemExit) raised in the sequencer's
thread is treated the same way and re-raised only after SAFE (and STORE, when there is data)
have run; one arriving during SAFE or STORE is held until they are done. During SAFE and STORE
an abort changes nothing (that is where the shot is going anyway); during ANALYSE it abandons
the analysis (the shot is kept). A held abort is used up when the shot (or `make_safe`) ends;
`clear_abort()` forgets one (a new operator intent).

STORE: whenever data was captured (also after an abort or a fault following the capture): the
raw shot file written atomically (rig/shot.py, rig/shotfile_writer.py). ANALYSE: in a worker thread,
bounded by timeouts.analyse_s; its result or its failure stored in the shot file
(rig.shot.analyse_and_record, the same code a campaign uses for a stored shot). An analysis
failure ends DONE with analysis_error set and exit code 4 (docs/exit-codes.md).

No printing: progress goes to the EventBus (rig/events.py).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hopkinson.drivers.errors import InstrumentError, InstrumentTimeout
from hopkinson.rig.config import RigConfig
from hopkinson.rig.errors import (
    EXIT_ABORTED,
    EXIT_ANALYSIS_FAILED,
    EXIT_DONE,
    HINT_SAFE_NOT_CONFIRMED,
    instrument_hint,
)
from hopkinson.rig.events import Analysed, EventBus, RigError, ShotFinished, StateEntered, Stored
from hopkinson.rig.instruments import Instruments
from hopkinson.rig.interlocks import InterlockReport, evaluate, read_readings
from hopkinson.rig.lock import command_line
from hopkinson.rig.logbook import Logbook, shot_log_path
from hopkinson.rig.sequencer.context import (
    POLL_INTERVAL_S,
    Abort,
    AbortRequest,
    AfterStore,
    BeforeFire,
    FireAuthorisation,
    Publisher,
    ShotContext,
)
from hopkinson.rig.sequencer.safe import DISPLAY_INTERLOCKS, SafeResult, make_rig_safe
from hopkinson.rig.sequencer.states import STATE_TEXT, State, check_transition
from hopkinson.rig.sequencer.steps import STEPS
from hopkinson.rig.shot import (
    AnalyseFn,
    RecordedAnalysis,
    ShotOutcome,
    ShotRequest,
    ShotRequestError,
    WorkResult,
    analyse_and_record,
    analysis_params,
    generated_shot_name,
    rescue_raw_shot,
    shot_analyser,
    shot_meta,
    store_raw_shot,
)

_log = logging.getLogger(__name__)


@dataclass
class _Failure:
    state: State
    detail: str  # "<instrument>: <why>"
    hint: str = ""
    source: str = ""
    codes: tuple[str, ...] = ()


class Sequencer:
    """Runs shots on connected instruments; see the module docstring.

    instruments: the connected drivers (rig/instruments.py); used only by the thread in
    run_shot while a shot runs. bus: where events go. analyse: the analysis computation
    (default: rig.shot.shot_analyser of the sequencer's configuration at the shot); tests may
    pass another.
    """

    def __init__(self, instruments: Instruments, config: RigConfig, bus: EventBus, *,
                 analyse: AnalyseFn | None = None, poll_interval_s: float = POLL_INTERVAL_S,
                 shot_log: bool = True, trace: bool = False) -> None:
        self.instruments = instruments
        self.shot_log = shot_log  # write <shot>.log.jsonl beside each shot file (rig/logbook.py)
        self.trace = trace  # and every instrument exchange in it
        self.config = config
        self.bus = bus
        self._analyse = analyse  # None: rig.shot.shot_analyser(self.config) at the shot
        self._poll_s = poll_interval_s
        self._lock = threading.Lock()
        self._run_lock = threading.Lock()
        self._state = State.IDLE
        self._abort = AbortRequest()
        self._events = Publisher(bus)
        self._last_report: InterlockReport | None = None

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

    @property
    def abort_requested(self) -> bool:
        """Is an abort held (asked for and not yet used up)?"""
        return self._abort.requested

    def abort(self, reason: str = "abort requested") -> None:
        """Ask for the shot to stop and go SAFE: held until honoured (module docstring).

        Any thread, any moment, idempotent; only sets a flag: the sequencer's own thread
        notices it and publishes the error, so no subscriber is called from the aborting thread.
        """
        self._abort.request(reason)

    def clear_abort(self) -> None:
        """Forget a held abort (the operator starts something new)."""
        self._abort.clear()

    def run_shot(self, request: ShotRequest, authorisation: FireAuthorisation, *,
                 before_fire: BeforeFire | None = None, after_store: AfterStore | None = None) -> ShotOutcome:
        """Run one shot to its end (blocking). ShotRequestError for a request that cannot be
        fired (nothing done; the analysis options are checked too); otherwise a ShotOutcome,
        SAFE having run on every path. before_fire / after_store: see ShotContext.

        The shot's file name is fixed before anything moves (a shot file of that name is
        refused), and its log (<name>.log.jsonl, rig/logbook.py) records the shot from CHECK on.
        """
        request.check(self.config)
        if request.shot_name is None:
            request = dataclasses.replace(request, shot_name=generated_shot_name())
        path = request.shot_path()
        if path.exists() or path.is_symlink():
            raise ShotRequestError(f"shot_name: {path} exists already: a shot file is never written over")
        params = analysis_params(request, self.config, {})
        if not self._run_lock.acquire(blocking=False):
            raise RuntimeError("a shot is already running on this sequencer")
        logbook: Logbook | None = None
        try:
            if self.shot_log:
                try:
                    logbook = Logbook(shot_log_path(path), command=command_line(), what=f"shot {path.name}")
                except OSError as exc:
                    raise ShotRequestError(f"{shot_log_path(path)}: the shot's log cannot be written "
                                           f"({exc.strerror or exc}); nothing was moved") from None
                logbook.attach(self.bus)
                if self.trace:
                    self.instruments.set_trace(logbook.trace)
            ctx = ShotContext(request, authorisation, self.instruments, self.config, self._abort, self._events,
                              params=params, poll_s=self._poll_s, before_fire=before_fire,
                              after_store=after_store)
            outcome = self._run(ctx)
            if logbook is not None:
                outcome = dataclasses.replace(outcome, log_path=logbook.path)
            self._abort.clear()  # honoured by this shot
        finally:
            if logbook is not None:
                if self.trace:
                    self.instruments.set_trace(None)
                logbook.close()
            self._run_lock.release()
        if ctx.interrupt is not None:
            raise ctx.interrupt
        return outcome

    def make_safe(self) -> tuple[bool, str | None]:
        """With no shot running, run SAFE (safe.py) and confirm it (blocking; the caller's
        thread must be the one that owns the instruments). A held abort is used up.

        Returns (confirmed, problem). The state does not change; SAFE's Reading, Note and
        RigError events are published. RuntimeError while a shot runs: abort() it instead.
        """
        if not self._run_lock.acquire(blocking=False):
            raise RuntimeError("a shot is running on this sequencer: abort() it and its SAFE runs")
        try:
            result = self._safe(None, controller_timed_out=False)
            self._abort.clear()
        finally:
            self._run_lock.release()
        if result.interrupt is not None:
            raise result.interrupt
        return result.confirmed, result.problem

    # -- the run ------------------------------------------------------------------------------
    def _run(self, ctx: ShotContext) -> ShotOutcome:
        failure: _Failure | None = None
        try:
            for state, step in STEPS:
                self._enter(ctx, state)
                # A held abort is honoured before a state's first action and after its last (up to
                # ARM: once the pulse is commanded, the record is worth keeping and CAPTURE runs).
                ctx.checkpoint(self.instruments.valves.name, f"starting {state.value}",
                               honour_abort=state != State.CAPTURE)
                step(ctx)
                if state in (State.CHECK, State.EVACUATE, State.CHARGE, State.ARM):
                    ctx.checkpoint(self.instruments.valves.name, f"finishing {state.value}")
        except Abort as exc:
            failure = _Failure(self._state, f"{exc.source}: {exc.reason}", exc.hint, exc.source, exc.codes)
        except InstrumentError as exc:
            if isinstance(exc, InstrumentTimeout) and exc.instrument == self.instruments.valves.name:
                ctx.controller_timed_out = True
            failure = _Failure(self._state, str(exc), instrument_hint(exc), exc.instrument)
        except Exception as exc:  # a bug or an unexpected library error: still make the rig safe
            _log.exception("unexpected error in %s", self._state)
            failure = _Failure(self._state, f"sequencer: unexpected error: {type(exc).__name__}: {exc}",
                               source="sequencer")
        except BaseException as exc:  # KeyboardInterrupt, SystemExit: deferred until SAFE has run
            ctx.interrupt = exc
            failure = _Failure(self._state, f"operator: interrupted ({type(exc).__name__})", source="operator")
        if failure is not None:
            self._shielded(ctx, lambda: self.bus.publish(RigError(
                state=failure.state, message=f"aborting: {failure.detail}", source=failure.source,
                hint=failure.hint, codes=failure.codes)))

        self._shielded(ctx, lambda: self._enter(ctx, State.SAFE))
        safe = self._safe(ctx, controller_timed_out=ctx.controller_timed_out)
        if safe.interrupt is not None and ctx.interrupt is None:
            ctx.interrupt = safe.interrupt

        path: Path | None = None
        store_error: str | None = None
        if ctx.captured is not None:
            path, store_error = self._store(ctx)

        results: dict[str, Any] | None = None
        analysis_error: str | None = None
        analysis_stored, analysis_to_redo = True, False
        if failure is None and safe.confirmed and store_error is None and path is not None:
            recorded = self._analyse_and_record(ctx, path)
            results, analysis_error, analysis_stored = recorded.results, recorded.error, recorded.stored
            analysis_to_redo = recorded.to_redo
            final = State.DONE if analysis_stored else State.FAULT
            if final == State.DONE and (self._abort.requested or ctx.interrupt is not None):
                final = State.ABORTED  # a signal or an abort once the shot had fired: exit 3 everywhere
        elif safe.confirmed and (store_error is None or path is not None):  # the record is kept
            final = State.ABORTED
        else:
            final = State.FAULT

        error = _message(ctx, failure, safe, path, store_error)
        if final == State.ABORTED and failure is None and store_error is None:
            error = (f"shot aborted after FIRE ({self._abort.reason or 'interrupted'}): the recorded data is kept in "
                     f"{path}" + ("; its analysis was not finished (`hopkinson analyse` it)" if analysis_to_redo else ""))
        if not analysis_stored:
            error = f"{analysis_error}; the raw shot is kept in {path} (free space, then `hopkinson analyse` it)"
        cause_hint = failure.hint if failure is not None else ""
        hint = cause_hint if safe.confirmed else " ".join(filter(None, (HINT_SAFE_NOT_CONFIRMED, cause_hint)))
        aborted_in = failure.state.value if failure is not None else (
            State.SAFE.value if not safe.confirmed else State.STORE.value if store_error else None)
        outcome = ShotOutcome(
            final_state=final.value,
            shot_path=path,
            results=results,
            error=error,
            exit_code=(EXIT_ABORTED if final != State.DONE else EXIT_ANALYSIS_FAILED if analysis_error else EXIT_DONE),
            aborted_in=aborted_in,
            fired=ctx.fired,
            fire_confirmed_by=ctx.fire_confirmed_by,
            analysis_error=analysis_error,
            analysis_to_redo=analysis_to_redo,
            safe_confirmed=safe.confirmed,
            warnings=tuple(ctx.warnings),
            hint=hint,
        )
        final_text = STATE_TEXT[final] if final != State.FAULT or not safe.confirmed else \
            "FAULT: the shot's record is not complete (read why above); the rig is safe"
        self._shielded(ctx, lambda: self._enter(ctx, final, final_text))
        self._shielded(ctx, lambda: self.bus.publish(ShotFinished(
            state=final.value, message=error or analysis_error or STATE_TEXT[final],
            final_state=final.value, exit_code=outcome.exit_code, fired=ctx.fired, safe_confirmed=safe.confirmed,
            shot_path=str(outcome.shot_path) if outcome.shot_path else None, error=error, hint=hint,
            analysis_error=analysis_error, aborted_in=aborted_in, warnings=tuple(ctx.warnings))))
        return outcome

    # -- state plumbing -----------------------------------------------------------------------
    def _enter(self, ctx: ShotContext, state: State, message: str | None = None) -> None:
        with self._lock:
            check_transition(self._state, state)
            self._state = state
        self._events.state = state
        ctx.start_clock(state)
        self.bus.publish(StateEntered(state=state.value, message=message or STATE_TEXT.get(state, state.value),
                                      timeout_s=ctx.timeout_s))

    def _shielded(self, ctx: ShotContext, action: Callable[[], Any]) -> Any:
        """Run `action`; an Exception is logged, an interrupt is held for after SAFE/STORE."""
        try:
            return action()
        except Exception:
            _log.exception("in %s", self._state)
        except BaseException as exc:
            if ctx.interrupt is None:
                ctx.interrupt = exc
        return None

    # -- SAFE, STORE, ANALYSE ---------------------------------------------------------------------
    def _safe(self, ctx: ShotContext | None, *, controller_timed_out: bool) -> SafeResult:
        disarm = ctx is None or ctx.captured is None  # a captured record stays in the digitizer
        result = make_rig_safe(self.instruments.valves, self.config, self._events,
                               digitizer=self.instruments.digitizer if disarm else None,
                               controller_timed_out=controller_timed_out, poll_s=self._poll_s,
                               untrusted_gauge=ctx.untrusted_gauge if ctx is not None else None)
        return result

    def _in_worker(self, ctx: ShotContext, work: Callable[[], Any], timeout_s: float, abandon_on_abort: bool,
                   name: str) -> WorkResult:
        """Run `work` in a daemon thread, publishing readings while waiting.

        Not finished: the timeout passed, or an abort/interrupt came and `abandon_on_abort`; the
        thread is then left to end on its own (a Python thread cannot be stopped) and its
        result is ignored.
        """
        def stopped() -> bool:
            return abandon_on_abort and (self._abort.requested or ctx.interrupt is not None)

        def why_not() -> str:
            if stopped():
                return f"{name} abandoned: {self._abort.reason or 'interrupted'}"
            return f"{name} did not finish within {timeout_s:g} s"

        if stopped():
            return WorkResult(False, why_not=why_not())  # asked to stop before it began: do not start it
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
                if ctx.interrupt is None:
                    ctx.interrupt = exc
            if not thread.is_alive():
                return WorkResult(True, box.get("value"), box.get("error"))
            if time.monotonic() >= deadline or stopped():
                return WorkResult(False, why_not=why_not())
            if readings_ok:  # the rig is safe: readings are for the display only
                try:
                    report = evaluate(read_readings(self.instruments, amplifier=False), self.config.limits,
                                      DISPLAY_INTERLOCKS)
                    self._events.reading(report)
                except Exception:
                    readings_ok = False

    def _store(self, ctx: ShotContext) -> tuple[Path | None, str | None]:
        """STORE the raw shot; returns (path, error): (the file, None) stored; (the rescued file
        in the user's data folder, why the shot folder failed) when only that could take it;
        (None, why) when the raw shot is lost."""
        self._shielded(ctx, lambda: self._enter(ctx, State.STORE))
        assert ctx.captured is not None
        request = ctx.request
        path = request.shot_path()
        meta = shot_meta(request, self.config, ctx.identities, ctx.captured)
        captured = ctx.captured
        done = self._in_worker(ctx, lambda: store_raw_shot(path, captured, meta), self.config.timeouts.store_s,
                               abandon_on_abort=False, name="store")
        if not done.finished:
            message = f"{path}: not written within {self.config.timeouts.store_s:g} s (the file may still appear)"
        elif done.error is not None:
            message = str(done.error) if str(done.error).startswith(str(path)) else f"{path}: {done.error}"
        else:
            self._shielded(ctx, lambda: self.bus.publish(Stored(state=State.STORE.value, message=f"raw shot stored "
                                                                f"in {path}", shot_path=str(path))))
            if ctx.after_store is not None:
                self._shielded(ctx, lambda: ctx.after_store(ctx, path))
            return path, None
        rescued = None
        if done.finished:  # the folder failed (full, read-only, vanished): the user's data folder
            kept = self._in_worker(ctx, lambda: rescue_raw_shot(path, captured, meta), self.config.timeouts.store_s,
                                   abandon_on_abort=False, name="rescue")
            rescued = kept.value if kept.finished and kept.error is None else None
        if rescued is not None:
            message += f"; the raw shot was saved instead in {rescued}"
        else:
            message += "; the raw shot is LOST: nowhere could take it"
        self._shielded(ctx, lambda: self.bus.publish(RigError(state=State.STORE.value,
                                                              message=f"STORE failed: {message}", source="sequencer",
                                                              hint="Check the shot folder: disk space, "
                                                                   "permissions.")))
        return rescued, message

    def _analyse_and_record(self, ctx: ShotContext, path: Path) -> RecordedAnalysis:
        """ANALYSE (rig.shot.analyse_and_record in a worker thread); never raises."""
        self._shielded(ctx, lambda: self._enter(ctx, State.ANALYSE))
        assert ctx.captured is not None
        captured = ctx.captured
        try:
            params = analysis_params(ctx.request, self.config, ctx.settings)  # with the gain read back
            raw = captured.raw_shot()
        except Exception as exc:
            recorded = RecordedAnalysis(None, f"analysis not started: {exc}")
        else:
            def run(work: Callable[[], Any]) -> WorkResult:
                done = self._in_worker(ctx, work, self.config.timeouts.analyse_s, abandon_on_abort=True,
                                       name="analysis")
                if not done.finished:
                    return WorkResult(False, why_not=f"{done.why_not} (re-analyse the stored shot)")
                return done

            recorded = analyse_and_record(path, raw, params, self._analyse or shot_analyser(self.config),
                                          amplifier_overloaded=bool(ctx.settings.get("amplifier_overloaded")),
                                          run=run)
        error = recorded.error
        self._shielded(ctx, lambda: self.bus.publish(Analysed(
            state=State.ANALYSE.value, message=error or f"analysed: {path}", shot_path=str(path), error=error)))
        return recorded


def _message(ctx: ShotContext, failure: _Failure | None, safe: SafeResult, path: Path | None,
             store_error: str | None) -> str | None:
    """The one-line error: which state, which instrument, why; what became of the rig and data."""
    if failure is None and safe.confirmed and store_error is None:
        return None
    parts = []
    if failure is not None:
        parts.append(f"shot aborted in {failure.state.value}: {failure.detail}")
    if safe.confirmed:
        if failure is not None:
            parts.append("rig safe (fire and fill valves closed, reservoir vented)")
    else:
        parts.append(f"SAFE NOT CONFIRMED: {safe.problem}; check the rig by hand")
    if store_error is not None:
        parts.append(f"STORE failed: {store_error}")
        if failure is None and safe.confirmed:
            parts.append("rig safe (fire and fill valves closed, reservoir vented)")
    elif path is not None:
        parts.append(f"the recorded data is kept in {path}")
    elif ctx.fire_confirmed_by is not None:
        parts.append(f"the shot was fired but nothing was recorded (confirmed by {ctx.fire_confirmed_by})")
    elif ctx.fired:
        parts.append("the fire command was sent but nothing confirms a shot, and nothing was recorded")
    return "; ".join(parts)
