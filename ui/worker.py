"""The panel's link to the rig, off the GUI thread.

Threads. Every instrument call runs on ONE rig I/O thread (the drivers are not thread-safe):
connecting, the idle readings (~2 Hz, driven by a QTimer in the GUI thread that only *submits*
work) and the shot itself (`Sequencer.run_shot`, blocking until DONE/ABORTED/FAULT). While a
shot runs, the idle poll is skipped: the sequencer publishes its own "reading" events.
`abort()` is the one call made from the GUI thread straight into the rig layer
(`Sequencer.abort` is thread-safe). Nothing here touches a widget.

Control of the rig. `start()` takes the rig's lock (rig/lock.py) before anything is connected:
a rig held by another shot, campaign or panel raises RigLockError (the command exits 2 naming
the holder). Once the valve controller is connected, its driver feeds the controller's link
watchdog (a heartbeat session) until `shutdown()`: a panel that dies or hangs leaves a rig
that vents itself.

Signals. `start()` also catches SIGINT, SIGTERM and SIGHUP (rig/signals.py; main thread only):
a signal aborts a running shot or campaign (or, idle, runs SAFE), then `interrupted` closes
the window; `shutdown()` waits for SAFE, and the command exits 3 (`interrupted_reason`).

A conditioner set by hand (`[amplifier] driver = "manual"`): `start_shot` and `start_campaign`
take the values the technician entered (ui.shot_setup); they become the link's rig config's
[amplifier] settings (what CHECK asks of the conditioner and ARM compares, what the shot file's
configuration records) and, first thing on the I/O thread, the conditioner's own
(`ManualConditioner.enter`), so `settings()` gives them to the shot file.

Events. The sequencer publishes RigEvents on an EventBus in the I/O thread; `RigLink.event`
(a Qt signal) carries them to the GUI thread: a signal emitted in another thread reaches a
receiver living in the GUI thread through Qt's queued connection. The other signals
(`links_changed`, `shot_finished`, `message`) work the same way.

ABORT always reaches the safe state:
- a shot is running (or queued on the I/O thread): `Sequencer.abort`, which holds the abort
  until the shot honours it (before anything moves, when pressed before the shot began);
- no shot is running: `Sequencer.make_safe` does SAFE's work (fire and fill closed, vent
  open, pump off, read back until confirmed and vented, within timeouts.safe_s) on the I/O thread.

`Background` runs pure computations (loading a shot file, preparing plot data) on a
separate worker thread and hands the result to a callback in the GUI thread.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, replace
from typing import Any

from PySide6.QtCore import QObject, QTimer, Signal, Slot

from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError
from hopkinson.rig.config import RigConfig
from hopkinson.rig.errors import instrument_hint, with_hint
from hopkinson.rig.events import EventBus, RigEvent
from hopkinson.rig.instruments import Instruments, make_instruments
from hopkinson.rig.interlocks import REQUIRED, evaluate, read_readings
from hopkinson.rig.lab_record import attach_recorder
from hopkinson.rig.lock import RigLock, command_line, rig_address
from hopkinson.rig.sequencer import FireAuthorisation, Sequencer
from hopkinson.rig.shot import ShotOutcome, ShotRequest
from hopkinson.rig.signals import SignalLatch

_log = logging.getLogger(__name__)

POLL_INTERVAL_MS = 500  # idle readings at ~2 Hz
RECONNECT_INTERVAL_S = 3.0  # a missing instrument is tried again at most this often
DIGITIZER_CHECK_INTERVAL_S = 2.0  # the idle digitizer is asked for its state this often

INSTRUMENT_KEYS = ("valve_controller", "digitizer", "amplifier")
INSTRUMENT_LABELS = {
    "valve_controller": "Valve / vacuum controller",
    "digitizer": "Digitizer",
    "amplifier": "Bridge amplifier",
}


@dataclass(frozen=True)
class InstrumentLink:
    """What the panel knows about one instrument's connection.

    status: "connected" (answering), "error" (connected, but its last command failed),
    "disconnected" (not reachable), "unknown" (not tried yet).
    """

    key: str
    address: str
    status: str = "unknown"
    identity: str = ""
    problem: str = ""

    @property
    def label(self) -> str:
        return INSTRUMENT_LABELS[self.key]

    @property
    def usable(self) -> bool:
        return self.status in ("connected", "error")


class RigLink(QObject):
    """Connection, idle readings and shots of one rig, for the panel (module docstring).

    config: the rig configuration; simulated_truth: the simulator's truth getter (simulation).
    """

    event = Signal(object)  # RigEvent, in the GUI thread
    links_changed = Signal(object)  # dict[str, InstrumentLink]
    shot_finished = Signal(object)  # ShotOutcome
    shot_failed = Signal(str)  # a shot that could not start or crashed: one line
    campaign_finished = Signal(object)  # rig.campaign_results.CampaignOutcome
    campaign_failed = Signal(str)  # a campaign that could not start or crashed: one line
    message = Signal(str, str)  # level ("info" | "warning" | "error"), text
    safe_done = Signal(bool, str)  # idle ABORT: confirmed?, what was done
    interrupted = Signal(str)  # a termination signal came: the reason ("interrupted (SIGTERM)")

    def __init__(self, config: RigConfig,
                 simulated_truth: Callable[[], dict[str, Any] | None] | None = None,
                 parent: QObject | None = None, poll_interval_ms: int = POLL_INTERVAL_MS,
                 take_lock: bool = True, catch_signals: bool = True) -> None:
        super().__init__(parent)
        self.config = config
        self.take_lock = take_lock
        self.catch_signals = catch_signals
        self.rig_lock: RigLock | None = None
        self.interrupted_reason = ""
        self.last_safe: tuple[bool, str] | None = None  # how the last SAFE ended: confirmed?, text
        self._latch: SignalLatch | None = None
        self.bus = EventBus()
        self.instruments: Instruments = make_instruments(config)
        self.instruments.simulated_truth = simulated_truth
        self.sequencer = Sequencer(self.instruments, config, self.bus)
        self._unsubscribe = self.bus.subscribe(self._on_bus_event)
        self.recorder = attach_recorder(self.bus, config)  # the lab's record (hopkinson.lab)
        self._io = ThreadPoolExecutor(max_workers=1, thread_name_prefix="rig-io")
        self._lock = threading.Lock()
        self._links = {
            "valve_controller": InstrumentLink("valve_controller", rig_address(config)),
            "digitizer": InstrumentLink("digitizer", config.digitizer.resource),
            "amplifier": InstrumentLink("amplifier", "set by hand (no link)" if config.amplifier.driver == "manual"
                                        else f"serial {config.amplifier.port}"),
        }
        self._last_try = dict.fromkeys(INSTRUMENT_KEYS, -1e9)
        self._last_digitizer_check = -1e9
        self._poll_future: Future[None] | None = None
        self._shot_future: Future[None] | None = None  # a shot or a campaign
        self._active_sequencer: Sequencer = self.sequencer
        self.campaign_runner: Any = None  # rig.campaign.CampaignRunner while a campaign runs
        self.shot_authorisation: FireAuthorisation | None = None  # a campaign shot confirmed one by one
        self._closed = False
        self._timer = QTimer(self)
        self._timer.setInterval(poll_interval_ms)
        self._timer.timeout.connect(self.poll)
        self.interrupted.connect(self._close_on_signal)

    # -- public (GUI thread) ----------------------------------------------------------------
    def start(self) -> None:
        """Take the rig's lock (RigLockError when another process holds it), catch the
        termination signals, connect the instruments and start the idle readings."""
        if self.take_lock and self.rig_lock is None:
            self.rig_lock = RigLock.acquire(self.config, command_line())
            if self.rig_lock.reclaimed is not None:
                self.message.emit("warning", f"took over the rig lock left by {self.rig_lock.reclaimed.describe()}, "
                                             "which is no longer running")
        if self.catch_signals and self._latch is None:
            self._latch = SignalLatch().__enter__()
            self._latch.on_signal(self.on_os_signal)
        self.poll()
        self._timer.start()

    def on_os_signal(self, reason: str) -> None:
        """A termination signal (any thread): abort (or SAFE when idle), then close the window."""
        self.interrupted_reason = reason
        if not self._closed:
            if self.shot_running:
                self.abort(reason)  # the shot (or campaign) goes SAFE and stops
            # then SAFE once more, confirmed by reading back: queued after the shot on the I/O thread
            with contextlib.suppress(RuntimeError):  # the panel closed meanwhile (its SAFE has run)
                self._io.submit(self._guarded, self._make_safe_task)
        self.interrupted.emit(reason)

    def safe_summary(self) -> str:
        """How the last SAFE ended, in words (for the exit line after a signal)."""
        if self.last_safe is None:
            return "nothing was running; the rig was left as it was"
        return self.last_safe[1]

    @Slot(str)
    def _close_on_signal(self, reason: str) -> None:
        self.message.emit("error", f"{reason}: making the rig safe and closing the panel")
        window = self.parent()
        if window is not None and hasattr(window, "close"):
            window.close()
        else:
            self.shutdown()

    @property
    def links(self) -> dict[str, InstrumentLink]:
        with self._lock:
            return dict(self._links)

    @property
    def all_connected(self) -> bool:
        return all(link.usable for link in self.links.values())

    @property
    def shot_running(self) -> bool:
        """A shot, or a campaign of shots, is running on the I/O thread."""
        future = self._shot_future
        return future is not None and not future.done()

    @property
    def campaign_running(self) -> bool:
        return self.shot_running and self.campaign_runner is not None

    @Slot()
    def poll(self) -> None:
        """Submit one idle poll (connect what is missing, read the gauges) unless one is pending
        or a shot runs."""
        if self._closed or self.shot_running:
            return
        if self._poll_future is not None and not self._poll_future.done():
            return
        self._poll_future = self._io.submit(self._guarded, self._poll_task)

    def retry_now(self) -> None:
        """Try every instrument that is not answering at the next poll (not in RECONNECT_INTERVAL_S)."""
        for key, link in self.links.items():
            if not link.usable:
                self._last_try[key] = -1e9
        self.poll()

    def start_shot(self, request: ShotRequest, conditioner: dict[str, Any] | None = None) -> FireAuthorisation:
        """Run `request` on the I/O thread; returns the authorisation FIRE gives. `conditioner`:
        the values of a conditioner set by hand (module docstring), entered first.

        Shots and campaigns queue on the one I/O thread: they never overlap (the panel
        disables ARM while one runs).
        """
        authorisation = FireAuthorisation()
        self.sequencer.clear_abort()  # a new shot: an abort left from an earlier one is forgotten
        self._active_sequencer = self.sequencer
        self._use_conditioner(conditioner)
        self._shot_future = self._io.submit(self._guarded,
                                            lambda: self._shot_task(request, authorisation, conditioner))
        return authorisation

    def start_campaign(self, run: Any, plan: Any, conditioner: dict[str, Any] | None = None,
                       confirm_each_s: float | None = None) -> None:
        """Run a campaign (rig.campaign.CampaignRunner on `run`, a RunFolder, and `plan`) on the
        I/O thread; `campaign_finished` or `campaign_failed` tells how it ended. Firing must
        have been authorised by the caller (rig.campaign_setup.check_authorisation), or
        `confirm_each_s` given: each shot then waits armed (at most that long) for its own
        authorisation, `shot_authorisation` (the panel's FIRE gives it, as for a single shot).
        `conditioner`: as for start_shot."""
        from hopkinson.rig.campaign import CampaignRunner

        self._use_conditioner(conditioner)
        self.shot_authorisation = None
        confirm = {} if confirm_each_s is None else {"confirm_each": self._new_authorisation,
                                                      "confirm_timeout_s": confirm_each_s}
        runner = CampaignRunner(run, plan, self.instruments, self.config, self.bus, **confirm)
        self.campaign_runner = runner
        self._active_sequencer = runner.sequencer
        self._shot_future = self._io.submit(self._guarded, lambda: self._campaign_task(runner, conditioner))

    def _new_authorisation(self, _shot: Any) -> FireAuthorisation:
        """A campaign shot's own authorisation (I/O thread), kept for the panel's FIRE: set
        before the shot's events go out, so the GUI thread sees it when FIRE lights."""
        authorisation = FireAuthorisation()
        self.shot_authorisation = authorisation
        return authorisation

    def pause_campaign(self) -> None:
        """Stop the campaign after the shot now running (resume later)."""
        runner = self.campaign_runner
        if runner is not None:
            runner.stop_after_shot("paused by the operator")

    def abort(self, reason: str = "ABORT pressed on the panel") -> None:
        """Stop the running shot and go SAFE; with no shot running, command the valves safe."""
        if self.shot_running:
            runner = self.campaign_runner
            if runner is not None:
                runner.abort(reason)  # aborts its shot and stops the campaign
            else:
                self._active_sequencer.abort(reason)  # thread-safe; held until the shot honours it
            return
        if self._closed:  # closing: shutdown() made the rig safe already
            return
        self._io.submit(self._guarded, self._make_safe_task)

    def shutdown(self, timeout_s: float = 30.0) -> None:
        """Abort a running shot, wait for SAFE, close the instruments (GUI thread; blocks)."""
        if self._closed:
            return
        self._closed = True
        self._timer.stop()
        if self.shot_running:
            self.abort("the panel is closing")
        wait([self._io.submit(self.instruments.close)], timeout=timeout_s)  # after any SAFE queued before it
        self._unsubscribe()
        self.recorder.close()
        self._io.shutdown(wait=False, cancel_futures=True)
        if self.rig_lock is not None:
            self.rig_lock.release()
        if self._latch is not None:
            self._latch.__exit__(None, None, None)
            self._latch = None

    # -- I/O thread -----------------------------------------------------------------------------
    def _guarded(self, task: Callable[[], None]) -> None:
        """Run a task; a bug becomes a message on the panel, never a silent dead thread."""
        try:
            task()
        except Exception as exc:  # a bug, not an instrument error: show it, keep the panel alive
            _log.exception("rig I/O task failed")  # the traceback goes to the log file, not to the technician
            self.message.emit("error", f"The panel's rig link met an internal error ({exc or type(exc).__name__}); "
                                       "the rig is unaffected. Report it with the panel's log.")

    def _on_bus_event(self, event: RigEvent) -> None:
        """Bus subscriber (sequencer's thread): forward to the GUI thread."""
        self.event.emit(event)

    def _set_link(self, key: str, **changes: Any) -> None:
        with self._lock:
            old = self._links[key]
            new = replace(old, **changes)
            self._links[key] = new
            links = dict(self._links)
        if new != old:
            self.links_changed.emit(links)

    def _device(self, key: str) -> Any:
        return {"valve_controller": self.instruments.valves, "digitizer": self.instruments.digitizer,
                "amplifier": self.instruments.amplifier}[key]

    def _key_of(self, exc: InstrumentError) -> str | None:
        names = {self.instruments.valves.name: "valve_controller",
                 self.instruments.digitizer.instrument: "digitizer",
                 self.instruments.amplifier.name: "amplifier"}
        return names.get(exc.instrument)

    def _instrument_failed(self, exc: InstrumentError) -> None:
        key = self._key_of(exc)
        if key is None:
            self.message.emit("error", with_hint(str(exc), instrument_hint(exc)))
            return
        was = self.links[key].status
        if isinstance(exc, InstrumentConnectionError):
            self._set_link(key, status="disconnected", problem=exc.problem)
            if key != "valve_controller":  # the Modbus driver reconnects on its next request
                self._device(key).close()
            self._last_try[key] = time.monotonic()
        else:
            self._set_link(key, status="error", problem=f"{exc.command!r}: {exc.problem}")
        if was != self.links[key].status or was == "connected":
            level = "warning" if key != "valve_controller" else "error"
            self.message.emit(level, with_hint(str(exc), instrument_hint(exc)) if level == "error" else str(exc))

    def _connect(self, key: str) -> None:
        device = self._device(key)
        self._last_try[key] = time.monotonic()
        try:
            device.connect()
        except InstrumentError as exc:
            device.close()
            status_before = self.links[key].status
            self._set_link(key, status="disconnected", problem=exc.problem)
            if status_before != "disconnected":
                self.message.emit("warning", f"{INSTRUMENT_LABELS[key]} not connected: {exc}")
            return
        if key == "valve_controller":
            try:  # this panel controls the rig: feed the controller's link watchdog
                device.start_heartbeat()
            except InstrumentError as exc:
                self.message.emit("error", f"the controller's link watchdog could not be started: {exc}")
        try:
            identity = device.identity()
        except InstrumentError as exc:  # identification is optional (e.g. Modbus device id)
            identity = f"(no identification: {exc.problem})"
        self._set_link(key, status="connected", identity=identity, problem="")
        self.message.emit("info", f"{INSTRUMENT_LABELS[key]} connected: {identity}")

    def _poll_task(self) -> None:
        now = time.monotonic()
        for key in INSTRUMENT_KEYS:
            if not self.links[key].usable and now - self._last_try[key] >= RECONNECT_INTERVAL_S:
                self._connect(key)
        links = self.links
        amp_ok = links["amplifier"].usable
        if links["valve_controller"].usable:
            try:
                readings = read_readings(self.instruments, amplifier=amp_ok, digitizer=False)
            except InstrumentError as exc:
                self._instrument_failed(exc)
            else:
                for key in ("valve_controller", "amplifier") if amp_ok else ("valve_controller",):
                    if self.links[key].status == "error":
                        self._set_link(key, status="connected", problem="")
                required = [n for n in REQUIRED["ARM"] if n != "digitizer" and (amp_ok or n != "amplifier")]
                report = evaluate(readings, self.config.limits, required)
                self.bus.publish(report.reading(self.sequencer.state, idle=True))
        if links["digitizer"].usable and now - self._last_digitizer_check >= DIGITIZER_CHECK_INTERVAL_S:
            self._last_digitizer_check = now
            try:
                self.instruments.digitizer.acquisition_state()
            except InstrumentError as exc:
                self._instrument_failed(exc)
            else:
                if self.links["digitizer"].status == "error":
                    self._set_link("digitizer", status="connected", problem="")

    def _missing_instruments(self) -> list[str]:
        return [link.label for link in self.links.values() if not link.usable]

    def _use_conditioner(self, values: dict[str, Any] | None) -> None:
        """The hand-set conditioner's values become the rig config's [amplifier] settings for
        the shots that follow (GUI thread; no instrument call)."""
        if values is None:
            return
        amp = replace(self.config.amplifier, gain=values["gain"], excitation_v=values["excitation_v"],
                      lowpass_hz=values["lowpass_hz"], sensitivity_v_per_m_s2=values["sensitivity_v_per_m_s2"] or 0.0,
                      identity=values["identity"])
        self.config = replace(self.config, amplifier=amp)
        self.sequencer.config = self.config

    def _enter_conditioner(self, values: dict[str, Any] | None) -> str | None:
        """Enter the values into the hand-set conditioner (I/O thread); what went wrong, or None."""
        if values is None:
            return None
        amplifier = self.instruments.amplifier
        try:
            amplifier.enter(**values)  # type: ignore[attr-defined]  (a ManualConditioner)
        except (ValueError, TypeError, AttributeError) as exc:
            return f"the conditioner's values were not taken: {exc}"
        self._set_link("amplifier", identity=amplifier.identity())  # the lamp shows what was entered
        return None

    def _shot_task(self, request: ShotRequest, authorisation: FireAuthorisation,
                   conditioner: dict[str, Any] | None = None) -> None:
        missing = self._missing_instruments()
        if missing:
            self.shot_failed.emit(f"cannot start the shot: not connected: {', '.join(missing)}")
            return
        problem = self._enter_conditioner(conditioner)
        if problem is not None:
            self.shot_failed.emit(f"cannot start the shot: {problem}")
            return
        try:
            outcome: ShotOutcome = self.sequencer.run_shot(request, authorisation)
        except Exception as exc:  # ShotRequestError (bad request) or a bug: one line for the operator
            self._after_shot()
            self.shot_failed.emit(str(exc) if str(exc) else type(exc).__name__)
            return
        self._after_shot()
        self.last_safe = (outcome.safe_confirmed, "the shot was aborted and the rig made safe" if outcome.safe_confirmed
                          else f"SAFE NOT CONFIRMED: {outcome.error}; check the rig by hand")
        self.shot_finished.emit(outcome)

    def _campaign_task(self, runner: Any, conditioner: dict[str, Any] | None = None) -> None:
        missing = self._missing_instruments()
        outcome, failure = None, None
        if missing:
            failure = f"cannot start the campaign: not connected: {', '.join(missing)}"
        elif (problem := self._enter_conditioner(conditioner)) is not None:
            failure = f"cannot start the campaign: {problem}"
        else:
            try:
                outcome = runner.run()
            except Exception as exc:  # a journal or plan problem (ConfigError) or a bug: one line
                failure = str(exc) if str(exc) else type(exc).__name__
        if self.campaign_runner is runner:
            self.campaign_runner = None
            self._active_sequencer = self.sequencer
        self._after_shot()
        if failure is not None:
            self.campaign_failed.emit(failure)
        else:
            self.campaign_finished.emit(outcome)

    def _after_shot(self) -> None:
        """The sequencer may have closed the digitizer's session after a failure: re-check it."""
        if not self.instruments.digitizer.connected:
            self._set_link("digitizer", status="disconnected", problem="session closed after the shot")
            self._last_try["digitizer"] = -1e9

    def _make_safe_task(self) -> None:
        """Idle ABORT: the sequencer's SAFE without a shot (Sequencer.make_safe)."""
        confirmed, problem = self.sequencer.make_safe()
        text = ("rig safe: fire and fill valves closed, vent open, pump off" if confirmed else
                f"SAFE NOT CONFIRMED: {problem}; check the rig by hand")
        self.last_safe = (confirmed, text)
        self.safe_done.emit(confirmed, text)


class Background(QObject):
    """Run a function on a worker thread; its result (or error) reaches a GUI-thread callback.

        background.run(load, on_done=show, on_error=report)
    """

    _finished = Signal(object)

    def __init__(self, parent: QObject | None = None, workers: int = 1) -> None:
        super().__init__(parent)
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="panel-worker")
        self._finished.connect(self._deliver)
        self._pending = 0
        self._closed = False

    @property
    def busy(self) -> bool:
        return self._pending > 0

    def run(self, fn: Callable[[], Any], on_done: Callable[[Any], None],
            on_error: Callable[[BaseException], None] | None = None) -> None:
        """Run `fn` off the GUI thread; after `shutdown` (the panel closing) nothing more runs."""
        if self._closed:
            _log.info("background task not run: the panel is closing")
            return
        self._pending += 1

        def task() -> None:
            try:
                result, error = fn(), None
            except Exception as exc:
                _log.exception("background task failed")
                result, error = None, exc
            self._finished.emit((on_done, on_error, result, error))

        self._pool.submit(task)

    @Slot(object)
    def _deliver(self, item: tuple[Any, Any, Any, BaseException | None]) -> None:
        self._pending -= 1
        on_done, on_error, result, error = item
        if self._closed:  # the window is closing: its widgets are not drawn on any more
            return
        if error is None:
            on_done(result)
        elif on_error is not None:
            on_error(error)

    def shutdown(self) -> None:
        self._closed = True
        self._pool.shutdown(wait=False, cancel_futures=True)
