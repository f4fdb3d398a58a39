"""The campaign runner: fire the shots of a plan one after another, journaled, resumable.

    run, plan = prepare_run(plan_path, out=None, resume=False)     # a new run folder (or the one to resume)
    check_authorisation(plan, yes)                                  # ConfigError (exit 2) unless authorised
    with open_instruments(config) as instruments:
        runner = CampaignRunner(run, plan, instruments, config, bus)
    outcome = runner.run()                                          # blocking; outcome.exit_code 0 / 3 / 4

`prepare_run` and `check_authorisation` are rig/campaign_setup.py's.

How a shot moves through the journal (rig/journal.py has the rules):

- the sequencer's before-fire hook (called after every check, immediately before the fire
  pulse is commanded) -> FIRING is committed; if that commit fails, the hook raises and the
  shot is aborted unfired;
- the sequencer's after-store hook (the raw file has its final name) -> RECORDED, with the
  file's uuid;
- the shot's end -> ANALYSED / ANALYSIS_FAILED when it was analysed; ABORTED when the
  sequencer is sure nothing was fired; UNKNOWN when the fire command went out but no raw
  file exists (an operator decides: `hopkinson campaign decide`).

Every event of the run (each shot's and the runner's own) goes into the run folder's
`campaign.log.jsonl` (rig/logbook.py), appended to by every resume; each shot also has its own
log beside its shot file.

On start (and on `--resume`) the journal settles what a dead process left (leftover *.tmp
removed, FIRING shots matched to their raw files). Shots recorded but not analysed are then
analysed from their files (no instrument needed) before the next shot is fired.

The runner stops at the first shot that does not end DONE (aborted to the safe state, or a
FAULT): the operator looks at the rig before anything else is fired; `--resume` continues.
`stop_after_shot()` (a pause) stops after the current shot; `abort(reason)` aborts the
current shot (SAFE runs) and stops; an abort asked for between shots is held by the sequencer
and stops the campaign before the next shot moves anything. Outcome exit codes (docs/exit-codes.md):
0 every planned shot is done (analysed or skipped); 4 every planned shot is done but some
analyses failed (the message and `analyses_failed` name them); 3 the campaign stopped with
shots left (aborted, paused, or waiting for an operator decision).

What a run tells (its progress, its outcome, each shot's result line) is rig/campaign_results.py's;
the simulation's fire log, an independent witness of every launch, rig/sim_fire_log.py's.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.rig.campaign_results import (
    CampaignOutcome,
    CampaignProgress,
    analyses_failed,
    result_info,
    resume_text,
    shot_end_text,
)
from hopkinson.rig.campaign_setup import check_plan, shot_request
from hopkinson.rig.errors import EXIT_BAD_INPUT, ConfigError
from hopkinson.rig.events import (
    CAMPAIGN_STATE,
    CampaignFinished,
    CampaignShotEnded,
    CampaignShotStarted,
    EventBus,
    Note,
    RigWarning,
)
from hopkinson.rig.journal import Journal, ShotState
from hopkinson.rig.level_control import (
    LevelChoice,
    LevelPoint,
    append_history,
    choose_pressure,
    history_path,
    measured_peak_m_s2,
    read_history,
)
from hopkinson.rig.lock import command_line
from hopkinson.rig.logbook import CAMPAIGN_LOG_NAME, Logbook
from hopkinson.rig.plan import CampaignPlan, PlannedShot
from hopkinson.rig.run_folder import RunFolder
from hopkinson.rig.shot import (
    AnalyseFn,
    ShotOutcome,
    analyse_and_record,
    analysis_params,
    record_analysis,
    shot_analyser,
)
from hopkinson.rig.shotfile import ShotFileError, read_shot, read_shot_meta, utc_now_iso

if TYPE_CHECKING:
    from hopkinson.rig.config import RigConfig
    from hopkinson.rig.instruments import Instruments
    from hopkinson.rig.sequencer import FireAuthorisation

EXIT_COMPLETE = 0
EXIT_STOPPED = 3
EXIT_ANALYSIS_FAILED = 4  # complete, but some analyses failed (rig/errors.py, docs/exit-codes.md)

S = ShotState


class CampaignRunner:
    """Runs a campaign's remaining shots; see the module docstring.

    instruments: the connected rig (rig.instruments); the runner's `sequencer` fires on them
    and publishes on `bus`. The runner journals each shot through the sequencer's before-fire
    and after-store hooks and publishes its own events (state "CAMPAIGN"):
    CampaignShotStarted, CampaignShotEnded (the journal state at a shot's end), Note, and
    CampaignFinished. analyse: the analysis computation (default rig.shot.shot_analyser(config));
    on_shot_start: called with the shot about to be fired (None after it), e.g. to tag a
    simulation fire log. confirm_each: firing not authorised for the whole campaign, each shot
    is confirmed: called with the shot about to be fired, it gives the FireAuthorisation the
    armed sequencer then waits for (at most confirm_timeout_s, as a single shot: the panel's FIRE).
    """

    def __init__(self, run: RunFolder, plan: CampaignPlan, instruments: Instruments, config: RigConfig,
                 bus: EventBus, *, analyse: AnalyseFn | None = None,
                 max_aborts: int = 3, on_shot_start: Callable[[PlannedShot | None], None] | None = None,
                 confirm_each: Callable[[PlannedShot], FireAuthorisation] | None = None,
                 confirm_timeout_s: float = 600.0) -> None:
        from hopkinson.rig.sequencer import Sequencer  # the drivers load only when shots are fired

        self.run_folder = run
        self.plan = plan
        self.config = config
        self.bus = bus
        self.max_aborts = max_aborts
        self._analyse = analyse or shot_analyser(config)
        self.sequencer = Sequencer(instruments, config, bus, analyse=self._analyse)
        self._on_shot_start = on_shot_start
        self._confirm_each = confirm_each
        self._confirm_timeout_s = confirm_timeout_s
        self._journal: Journal | None = None
        self._current: CampaignProgress | None = None
        self._stop = threading.Event()
        self._stop_reason = ""
        self._mark_failure: str | None = None
        self._lock = threading.Lock()

    # -- control (any thread) ----------------------------------------------------------------
    @property
    def current(self) -> CampaignProgress | None:
        """The shot being fired (None between shots)."""
        return self._current

    def stop_after_shot(self, reason: str = "paused by the operator") -> None:
        """Finish the current shot, then stop (resume later with --resume)."""
        with self._lock:
            if not self._stop.is_set():
                self._stop_reason = reason
                self._stop.set()

    def abort(self, reason: str = "aborted by the operator") -> None:
        """Abort the current shot (the sequencer makes the rig safe) and stop the campaign; held
        by the sequencer when it comes between shots."""
        self.stop_after_shot(reason)
        self.sequencer.abort(reason)

    # -- the run -----------------------------------------------------------------------------
    def run(self) -> CampaignOutcome:
        """Check the plan, open (or resume) the journal, analyse what is pending, fire what is left."""
        check_plan(self.plan, self.config, self._history())
        journal = Journal.open(self.run_folder, self.plan, max_aborts=self.max_aborts)
        self._journal = journal
        fired: list[str] = []
        last: ShotOutcome | None = None
        logbook: Logbook | None = None
        try:
            logbook = Logbook(self.run_folder.path / CAMPAIGN_LOG_NAME, command=command_line(),
                              what=f"campaign {self.run_folder.campaign_id}").attach(self.bus)
        except OSError as exc:  # the journal is the record that matters: say so, go on
            self.bus.publish(RigWarning(state=CAMPAIGN_STATE, message=f"the campaign log cannot be written: {exc}"))
        try:
            for item in journal.resume_report:
                self._note(resume_text(item))
            for shot in journal.pending_analysis():
                self._analyse_from_file(shot)
            stop_message = ""
            while not self._stop.is_set():
                shot = journal.next_shot()
                if shot is None:
                    break
                last = self._fire(shot)
                if last.fired:
                    fired.append(shot.id)
                if not last.done:
                    stop_message = f"{shot.id}: {last.error or 'shot ended in ' + last.final_state}"
                    break
            if self._stop.is_set() and not stop_message:
                stop_message = self._stop_reason
            summary = journal.summary()
            redo = [s.id for s in journal.pending_analysis()]
            if redo and summary["complete"]:  # every shot fired, but an analysis was interrupted
                summary = {**summary, "complete": False}
                stop_message = stop_message or (f"the analysis of {', '.join(redo)} was interrupted or not stored: "
                                                "--resume redoes it")
            exit_code, message = self._conclusion(summary, stop_message)
            self.bus.publish(CampaignFinished(state=CAMPAIGN_STATE, message=message, exit_code=exit_code,
                                              run_folder=str(self.run_folder.path)))
            return CampaignOutcome(self.run_folder.path, exit_code, message, summary, fired,
                                   list(journal.resume_report), last)
        except ConfigError as exc:  # found once the run began (a shot it cannot plan): the run ends here
            self.bus.publish(CampaignFinished(state=CAMPAIGN_STATE, message=str(exc), exit_code=EXIT_BAD_INPUT,
                                              run_folder=str(self.run_folder.path)))
            raise
        finally:
            self._current = None
            self._journal = None
            journal.close()
            if logbook is not None:
                logbook.close()

    def _conclusion(self, summary: dict[str, Any], stop_message: str) -> tuple[int, str]:
        counts = summary["by_state"]
        done = counts[S.ANALYSED.value] + counts[S.ANALYSIS_FAILED.value] + counts[S.SKIPPED.value]
        failed = analyses_failed(summary)
        note = (f" ({len(failed)} with a failed analysis: {', '.join(failed)}; the raw shots are kept, "
                "`hopkinson analyse` them)") if failed else ""
        if summary["complete"]:
            code = EXIT_ANALYSIS_FAILED if failed else EXIT_COMPLETE
            return code, f"campaign complete: {done} of {summary['total']} shots done{note}"
        parts = [f"campaign stopped with {done} of {summary['total']} shots done{note}"]
        if stop_message:
            parts.append(stop_message)
        if summary["needs_decision"]:
            ids = ", ".join(summary["needs_decision"])
            parts.append(f"may have been fired without a record, an operator decides: {ids} "
                         f"(hopkinson campaign decide {self.run_folder.path} SHOT_ID retry|skip)")
        if summary["aborted_out"]:
            parts.append(f"aborted {self.max_aborts} times, not retried: {', '.join(summary['aborted_out'])}")
        parts.append(f"continue with --resume --out {self.run_folder.path}")
        return EXIT_STOPPED, "; ".join(parts)

    def _progress(self, shot: PlannedShot, pressure_bar: float | None = None) -> CampaignProgress:
        pressure = pressure_bar if pressure_bar is not None else shot.pressure_bar
        return CampaignProgress(shot.index + 1, len(self.plan.shots), shot.id, pressure or 0.0, shot.projectile)

    # -- automatic level control (rig/level_control.py) ------------------------------------------
    def _history_path(self) -> Path:
        return history_path(self.run_folder.path.parent)

    def _history(self) -> list[LevelPoint]:
        return read_history(self._history_path())

    def _level_choice(self, shot: PlannedShot) -> LevelChoice | None:
        """The pressure for a target-level shot from the entry's analysed shots, else the rig's history."""
        if shot.target_peak_m_s2 is None:
            return None
        assert self._journal is not None
        entry_shots = []
        for other in self.plan.shots:
            if other.entry != shot.entry or other.index >= shot.index:
                continue
            info = self._journal.status(other.id).info
            if isinstance(info.get("peak_m_s2"), int | float) and isinstance(info.get("pressure_bar"), int | float):
                entry_shots.append(LevelPoint(other.projectile, float(info["pressure_bar"]), float(info["peak_m_s2"])))
        limits = self.config.limits
        try:
            return choose_pressure(shot.target_peak_m_s2, shot.projectile, self._history(), entry_shots,
                                   min_pressure_bar=limits.min_pressure_bar, max_pressure_bar=limits.max_pressure_bar,
                                   rig=self.config.bar.rig())
        except ValueError as exc:  # the bar model's speed search did not settle: fire nothing at a guess
            raise ConfigError(f"{self.plan.path}: shots[{shot.entry}] ({shot.id}): a target level needs the bar "
                              f"model: {exc}; this shot was not fired (--resume continues)") from None

    def _remember_level(self, shot: PlannedShot, pressure_bar: float | None, results: dict[str, Any] | None) -> None:
        """An analysed shot's pressure → peak into the rig's history (a failure is a warning)."""
        peak = measured_peak_m_s2(results)
        if peak is None or pressure_bar is None:
            return
        try:
            append_history(self._history_path(), LevelPoint(shot.projectile, float(pressure_bar), peak),
                           campaign_id=self.run_folder.campaign_id, shot_id=shot.id, utc=utc_now_iso())
        except OSError as exc:
            self.bus.publish(RigWarning(state=CAMPAIGN_STATE, message=f"the level history cannot be written: {exc}"))

    def _fire(self, shot: PlannedShot) -> ShotOutcome:
        """One shot through the sequencer, journaled by its hooks, settled at its end."""
        assert self._journal is not None
        level = self._level_choice(shot)
        request = shot_request(self.plan, shot, self.run_folder, level, campaign_uuid=self._journal.campaign_uuid)
        current = self._current = self._progress(shot, request.pressure_bar)
        self._mark_failure = None
        if self._on_shot_start is not None:
            self._on_shot_start(shot)
        target = "" if level is None else (f" (target {level.target_peak_m_s2 / 9.80665:.4g} g, pressure from "
                                           f"{level.basis}{', held at the rig limit' if level.held_at_limit else ''})")
        self.bus.publish(CampaignShotStarted(
            state=CAMPAIGN_STATE,
            message=f"shot {shot.id}: {request.pressure_bar:.4g} bar, projectile No. {shot.projectile}{target}",
            shot_id=shot.id, index=current.index, total=current.total, pressure_bar=request.pressure_bar,
            projectile=shot.projectile, target_peak_m_s2=shot.target_peak_m_s2))
        from hopkinson.rig.sequencer import FireAuthorisation

        firing_info: dict[str, Any] = {"pressure_bar": request.pressure_bar}
        if level is not None:
            firing_info.update(target_peak_m_s2=level.target_peak_m_s2, level_basis=level.basis)
        if self._confirm_each is None:
            authorisation = FireAuthorisation.pre_given()
        else:
            authorisation = self._confirm_each(shot)
            request = dataclasses.replace(request, confirm_timeout_s=self._confirm_timeout_s)
        try:
            outcome = self.sequencer.run_shot(request, authorisation,
                                              before_fire=lambda _ctx: self._mark_firing(shot.id, firing_info),
                                              after_store=lambda _ctx, path: self._on_stored(shot.id, Path(path)))
            self._settle(shot, outcome)
            if outcome.done and outcome.analysis_error is None:
                self._remember_level(shot, request.pressure_bar, outcome.results)
            return outcome
        finally:
            if self._on_shot_start is not None:
                self._on_shot_start(None)
            self._current = None

    def _mark_firing(self, sid: str, info: dict[str, Any] | None = None) -> None:
        """The before-fire hook: FIRING on disk (with the pressure chosen and any target level)
        before the pulse is commanded, or no shot."""
        assert self._journal is not None
        try:
            self._journal.mark(sid, S.FIRING, **(info or {}))
        except Exception as exc:  # never fire a shot the journal does not know is firing
            self._mark_failure = f"campaign journal: FIRING of {sid} could not be recorded ({exc})"
            raise RuntimeError(self._mark_failure) from exc

    def _on_stored(self, sid: str, path: Path) -> None:
        """The after-store hook: RECORDED once the raw file has its final name."""
        try:
            self._mark_recorded(sid, path)
        except Exception as exc:  # settled again when the shot ends
            self._mark_failure = f"campaign journal: RECORDED of {sid} could not be recorded ({exc})"

    def _mark_recorded(self, sid: str, path: Path) -> None:
        assert self._journal is not None
        if self._journal.status(sid).state != S.FIRING:
            return
        meta = read_shot_meta(path)
        self._journal.mark(sid, S.RECORDED, uuid=meta.uuid, file=path.name)

    def _settle(self, shot: PlannedShot, outcome: ShotOutcome) -> None:
        """Bring the journal in line with how the shot ended."""
        journal = self._journal
        assert journal is not None
        sid = shot.id
        path = self.run_folder.shot_path(sid)
        state = journal.status(sid).state
        has_file = outcome.shot_path is not None and path.exists()
        if has_file and state == S.FIRING:
            self._mark_recorded(sid, path)
            state = journal.status(sid).state
        if state == S.RECORDED:
            if outcome.done and outcome.analysis_error is None:
                journal.mark(sid, S.ANALYSED, **result_info(outcome.results))
            elif outcome.done or outcome.analysis_to_redo:
                journal.mark(sid, S.ANALYSIS_FAILED, error=outcome.analysis_error or outcome.error,
                             redo=outcome.analysis_to_redo)
            elif outcome.final_state != "FAULT":  # recorded, then aborted: analyse the stored data
                self._analyse_from_file(shot)
                return
        elif state == S.FIRING:
            rescued = outcome.shot_path if outcome.shot_path is not None and outcome.shot_path != path else None
            if outcome.fired and rescued is not None and rescued.exists():
                # the run folder could not take the raw shot; rig.shot.rescue_raw_shot kept it
                journal.mark(sid, S.UNKNOWN, rescued=str(rescued),
                             reason=f"fired; the run folder could not take the raw shot, which was rescued to "
                                    f"{rescued}: free the folder, move that file to {path} and resume "
                                    "(`campaign run --resume` records and analyses it, never fires it again)")
            elif outcome.fired:
                journal.mark(sid, S.UNKNOWN, reason=outcome.error or "the fire command went out, but no raw file "
                                                                    "was stored")
            else:
                journal.mark(sid, S.ABORTED, reason=outcome.error or self._mark_failure or "aborted")
        elif state in (S.PLANNED, S.ABORTED):
            journal.mark(sid, S.ABORTED, reason=outcome.error or self._mark_failure or "aborted before FIRE")
        self._shot_ended(shot, shot_end_text(journal.status(sid), outcome), outcome.final_state)

    def _shot_ended(self, shot: PlannedShot, message: str, final_state: str | None) -> None:
        assert self._journal is not None
        progress = self._current or self._progress(shot)
        self.bus.publish(CampaignShotEnded(
            state=CAMPAIGN_STATE, message=message, shot_id=shot.id, index=progress.index, total=progress.total,
            journal_state=self._journal.status(shot.id).state.value, final_state=final_state))

    def _analyse_from_file(self, shot: PlannedShot) -> None:
        """Analyse a RECORDED shot from its raw file and store the result (or the failure), with
        the sequencer's own ANALYSE code (rig.shot.analyse_and_record)."""
        assert self._journal is not None
        self._current = self._progress(shot)
        path = self.run_folder.shot_path(shot.id)
        self._note(f"analysing the recorded shot {path.name}")
        results: dict[str, Any] | None = None
        redo = False
        try:
            stored = read_shot(path)
            if stored.raw is None:
                raise ShotFileError(f"{path}: holds no raw data")
        except ShotFileError as exc:
            error: str | None = str(exc)
            with contextlib.suppress(Exception):
                record_analysis(path, None, error)  # the journal still says why
        else:
            # The rig constants of this run's configuration; the amplifier gain read back at
            # the shot (stored in the file) wins, as in the sequencer's own analysis.
            settings = dict(stored.meta.config.get("shot_settings", {}))
            try:
                params = analysis_params(shot_request(self.plan, shot, self.run_folder,
                                                      pressure_bar=stored.meta.pressure_bar), self.config, settings)
            except Exception as exc:
                results, error = None, f"analysis not started: {exc}"
                with contextlib.suppress(Exception):
                    record_analysis(path, None, error)
            else:
                recorded = analyse_and_record(path, stored.raw, params, self._analyse,
                                              amplifier_overloaded=bool(settings.get("amplifier_overloaded")))
                results, error, redo = recorded.results, recorded.error, recorded.to_redo
        if error is None:
            self._journal.mark(shot.id, S.ANALYSED, **result_info(results))
            self._remember_level(shot, stored.meta.pressure_bar, results)
        else:
            self._journal.mark(shot.id, S.ANALYSIS_FAILED, error=error, redo=redo)
        self._shot_ended(shot, "ANALYSED" if error is None else f"ANALYSIS_FAILED: {error}", None)
        self._current = None

    def _note(self, message: str) -> None:
        self.bus.publish(Note(state=CAMPAIGN_STATE, message=message))

