"""`hopkinson campaign`: run a campaign plan, see where a run stands, decide on doubtful shots.

    hopkinson campaign run PLAN.toml [--sim [--sim-config PATH] [--sim-fault NAME ...]
                       [--sim-fire-log PATH]] [--config PATH] [--yes] [--out DIR] [--resume]
                       [--report pdf,html | --no-report] [--json]
    hopkinson campaign status RUN_FOLDER [--json]
    hopkinson campaign decide RUN_FOLDER SHOT_ID {retry,skip} [--note TEXT]

run: fires the plan's shots in order into a run folder (rig/run_folder.py): a new folder
`--out DIR` (default runs/<plan name>-<UTC time>), or with --resume the run folder `--out DIR`
(default: the newest runs/<plan name>-* folder), continuing after a crash, a kill -9 or an
abort with no planned shot lost and none fired twice (rig/journal.py). Firing must be
authorised by the plan (authorise_firing = true) or by --yes; otherwise the command stops
with exit code 2 before anything is created, started or fired. Progress goes to stderr as
plain lines ("[3/8] s002-r1 CHARGE 1.20 bar"); at the end stdout names the run folder and the
report (report/report.pdf and report/report.html in the run folder, written also when the
campaign stopped early, from the shots done so far).

Exit codes (docs/exit-codes.md, `hopkinson campaign run --help`): 0 every planned shot done
(analysed or skipped); 2 bad input or configuration, or firing not authorised (nothing fired);
3 the campaign stopped with shots left: a shot aborted to the safe state, a FAULT, shots that
may have been fired without a record (UNKNOWN: decide them with `campaign decide`, then
--resume), or a signal (SIGINT, SIGTERM, SIGHUP: the current shot is aborted to the safe state
first); 4 every planned shot done but some analyses failed (the message says how many and
which); 5 every planned shot done but a lab record is in neither the database nor the spool
(`hopkinson lab import` it). The --json object's `exit_code` is always the exit code, and
`analyses_failed` lists the shots whose analysis failed.

status: the journal's summary (counts by state, shots needing a decision). It opens the
journal, so it refuses while a campaign runs in that folder.
decide: an operator's decision on an UNKNOWN shot: "retry" (fire it again) or "skip".
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path
from typing import Any

from hopkinson.rig.cli.main import add_rig_arguments, emit_json, rig_config_path
from hopkinson.rig.cli.shot import add_log_arguments
from hopkinson.rig.errors import EXIT_ABORTED, ConfigError, exit_codes_help
from hopkinson.rig.plan_limits import CONFIRM_ABOVE_SHOTS

REPORT_FORMATS = ("pdf", "html")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `campaign` sub-command and its own sub-commands."""
    p = subparsers.add_parser("campaign", help="run a campaign plan (many shots), resumable",
                              description="Campaigns: run a TOML plan of shots, see a run's state, decide "
                                          "on shots that may have been fired without a record.")
    sub = p.add_subparsers(dest="campaign_command", metavar="ACTION", required=True)

    run = sub.add_parser("run", help="fire a plan's shots into a run folder (--resume continues one)",
                         description="Fire the shots of PLAN.toml in order, journaled in a run folder; "
                                     "--resume continues after a crash or kill with no shot lost or fired twice.",
                         epilog=exit_codes_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("plan", type=Path, metavar="PLAN.toml", help="campaign plan (config/campaigns/example.toml)")
    add_rig_arguments(run)
    run.add_argument("--sim-fire-log", type=Path, metavar="PATH",
                     help="with --sim: append one JSON line per simulated launch here (a witness for tests)")
    run.add_argument("--yes", action="store_true", help="authorise firing (when the plan does not)")
    run.add_argument("--out", type=Path, metavar="DIR",
                     help="the run folder (default: runs/<plan name>-<UTC time>; with --resume the newest one)")
    run.add_argument("--resume", action="store_true", help="continue the run folder --out (or the newest one)")
    run.add_argument("--report", default="pdf,html", metavar="FORMATS",
                     help="report formats written into the run folder's report/ (default %(default)s)")
    run.add_argument("--no-report", action="store_true", help="do not write the report at the end")
    run.add_argument("--confirm-above", type=int, default=CONFIRM_ABOVE_SHOTS, metavar="N",
                     help="a plan of more than N shots needs --shots N_TOTAL (default %(default)s)")
    run.add_argument("--shots", type=int, metavar="N",
                     help="confirm the number of shots of a plan larger than --confirm-above")
    add_log_arguments(run)
    run.set_defaults(func=run_campaign_command)

    status = sub.add_parser("status", help="the journal summary of a run folder")
    status.add_argument("run_folder", type=Path, metavar="RUN_FOLDER")
    status.add_argument("--json", action="store_true", help="the summary as one JSON object")
    status.set_defaults(func=status_command)

    decide = sub.add_parser("decide", help="retry or skip a shot that may have been fired without a record")
    decide.add_argument("run_folder", type=Path, metavar="RUN_FOLDER")
    decide.add_argument("shot_id", metavar="SHOT_ID")
    decide.add_argument("decision", choices=("retry", "skip"))
    decide.add_argument("--note", default="", help="why (kept in the journal)")
    decide.set_defaults(func=decide_command)


def report_formats(text: str) -> list[str]:
    """"pdf,html" -> ["pdf", "html"]; ConfigError for an unknown format."""
    formats = [f.strip().lower() for f in text.split(",") if f.strip()]
    unknown = [f for f in formats if f not in REPORT_FORMATS]
    if unknown or not formats:
        raise ConfigError(f"--report: {text!r}: formats are {', '.join(REPORT_FORMATS)} (comma-separated)")
    return formats


def run_campaign_command(args: argparse.Namespace) -> int:
    from hopkinson.rig.signals import SignalLatch

    with SignalLatch() as latch:  # from here on, every signal goes SAFE (exit 3)
        return _run_campaign(args, latch)


def _run_campaign(args: argparse.Namespace, latch: Any) -> int:
    from hopkinson.rig.campaign import CampaignRunner
    from hopkinson.rig.campaign_setup import check_authorisation, check_plan, prepare_run
    from hopkinson.rig.cli.shot import (
        not_recorded_exit,
        report_reclaimed,
        subscribe_outputs,
        tell_unshown_warnings,
    )
    from hopkinson.rig.config import load_rig_config, load_sim_config
    from hopkinson.rig.control import controlled_rig
    from hopkinson.rig.events import EventBus
    from hopkinson.rig.instruments import with_sim_channels
    from hopkinson.rig.lab_record import attach_recorder
    from hopkinson.rig.lock import command_line
    from hopkinson.rig.plan import check_shot_count, load_plan
    from hopkinson.rig.sim_fire_log import FireLog, attach_fire_log

    if not args.sim and (args.sim_fault or args.sim_fire_log):
        raise ConfigError("--sim-fault and --sim-fire-log need --sim")
    formats = [] if args.no_report else report_formats(args.report)
    config = load_rig_config(rig_config_path(args))
    plan = load_plan(args.plan)
    check_authorisation(plan, args.yes)  # exit 2 before anything is created or fired
    sim_config = load_sim_config(args.sim_config) if args.sim else None
    # every entry against the rig's limits and channels (with --sim: those the simulator will give), every
    # analysis option
    check_plan(plan, with_sim_channels(config, sim_config) if sim_config is not None else config)
    check_shot_count(plan, args.confirm_above, args.shots)
    fire_log = FireLog(args.sim_fire_log) if args.sim_fire_log else None

    bus = EventBus()
    printer = ProgressPrinter(verbose=args.verbose) if not (args.json or args.json_events) else None
    with contextlib.ExitStack() as stack:
        truth = None
        if sim_config is not None:
            from hopkinson.rig.sim_session import sim_session

            session = stack.enter_context(sim_session(config, sim_config, args.sim_fault))
            config, truth = session.config, session.simulated_truth
            if fire_log is not None:
                attach_fire_log(session.world, fire_log)
        control = stack.enter_context(controlled_rig(config, command_line(), truth))
        run, plan = prepare_run(args.plan, args.out, args.resume)
        if printer is not None:
            bus.subscribe(printer)
        subscribe_outputs(stack, bus, args, what=f"campaign {run.path.name}", lines=False)
        recorder = attach_recorder(bus, config, stack)  # the lab's record (hopkinson.lab)
        report_reclaimed(control)
        runner = CampaignRunner(run, plan, control.instruments, config, bus,
                                on_shot_start=fire_log.set_shot if fire_log is not None else None)
        runner.sequencer.trace = args.trace
        if printer is not None:
            printer.runner = runner
        latch.on_signal(runner.abort)  # aborts the shot in progress, or holds the abort for the next
        outcome = runner.run()
        safe_again = None
        if latch.received is not None and (outcome.last_shot is None or outcome.last_shot.done):
            safe_again = runner.sequencer.make_safe()  # the signal came between shots: SAFE all the same

    reports: list[str] = []
    if formats:
        reports = _write_report(run.path, formats)
    tell_unshown_warnings(args, recorder.messages)  # the lab record's, when no progress line showed them
    recorded = not_recorded_exit(recorder, outcome.exit_code)  # 5 for a done campaign whose lab record is lost
    exit_code = EXIT_ABORTED if latch.received is not None else recorded
    if args.json:  # its exit_code is the process's
        emit_json({**outcome.to_dict(), "exit_code": exit_code, "reports": reports,
                   "interrupted": latch.reason if latch.received is not None else None})
    elif not args.json_events:
        print(f"run folder: {run.path}", flush=True)
        for path in reports:
            print(f"report: {path}", flush=True)
    if latch.received is not None:
        rig = ("SAFE NOT CONFIRMED: check the rig by hand" if safe_again is not None and not safe_again[0]
               else "the current shot was aborted and the rig made safe")
        sys.stderr.write(f"hopkinson: error: {latch.reason}: {rig}; {outcome.message}\n")
        return exit_code
    if outcome.exit_code != 0:
        sys.stderr.write(f"hopkinson: error: {outcome.message}\n")
    return exit_code


def _write_report(run_folder: Path, formats: list[str]) -> list[str]:
    """The run's report in each format; a failure is a warning (the shots are what matters)."""
    from hopkinson.rig.report_data import write_run_report

    try:
        return [str(p) for p in write_run_report(run_folder, formats)]
    except Exception as exc:  # noqa: BLE001 - any report failure: say so, keep the exit code
        sys.stderr.write(f"hopkinson: warning: the report could not be written: {exc}\n")
        return []


class ProgressPrinter:
    """Prints the campaign's progress on stderr as plain lines with their UTC time (works without
    a terminal):

        21:16:26.123 [3/8] s002-r1 START 1.2 bar, projectile No. 3
        21:16:26.301 [3/8] s002-r1 CHARGE
        21:16:26.802 [3/8] s002-r1 CHARGE 1.20 bar
        21:16:29.417 [3/8] s002-r1 ANALYSED order 4, ...
    """

    def __init__(self, stream: Any = None, verbose: bool = False) -> None:
        self.stream = stream
        self.verbose = verbose
        self.runner: Any = None

    def __call__(self, event: Any) -> None:
        from hopkinson.rig.cli.output import clock, write_line
        from hopkinson.rig.events import (
            CampaignFinished,
            CampaignShotEnded,
            CampaignShotStarted,
            Note,
            Reading,
            RigError,
            RigWarning,
            StateEntered,
            StepProgress,
        )

        current = self.runner.current if self.runner is not None else None
        prefix = current.prefix if current is not None else "campaign:"
        line = None
        if isinstance(event, CampaignShotStarted):
            line = f"[{event.index}/{event.total}] {event.shot_id} START {event.pressure_bar:.4g} bar, " \
                   f"projectile No. {event.projectile}"
            if event.target_peak_m_s2 is not None:
                line += f" (target {event.target_peak_m_s2 / 9.80665:.5g} g)"
        elif isinstance(event, CampaignShotEnded):
            line = f"[{event.index}/{event.total}] {event.shot_id} {event.message}"
        elif isinstance(event, CampaignFinished):
            line = f"campaign: {event.message}" if event.exit_code == 0 else f"campaign: ! {event.message}"
        elif isinstance(event, StateEntered):
            line = f"{prefix} {event.state}"
        elif isinstance(event, StepProgress):
            if event.state == "CHARGE" and event.reservoir_pressure_bar is not None:
                line = f"{prefix} CHARGE {event.reservoir_pressure_bar:.2f} bar"
            else:
                line = f"{prefix} {event.state} {event.message}"
        elif isinstance(event, RigError):
            line = f"{prefix} {event.state} ! {event.message}" + (f" → {event.hint}" if event.hint else "")
        elif isinstance(event, RigWarning):
            line = f"{prefix} {event.state} warning: {event.message}"
        elif isinstance(event, Note):
            line = f"{prefix} {event.message}" if event.state == "CAMPAIGN" else f"{prefix} {event.state}   {event.message}"
        elif self.verbose and isinstance(event, Reading):
            line = f"{prefix} {event.state} {event.reservoir_pressure_bar:.3f} bar, {event.fixture_vacuum_mbar:.1f} mbar"
        if line is not None:
            write_line(self.stream or sys.stderr, f"{clock(event)} {line}")


def status_command(args: argparse.Namespace) -> int:
    from hopkinson.rig.journal import Journal

    with Journal.open(args.run_folder) as journal:
        summary = journal.summary()
    if args.json:
        emit_json(summary)
        return 0
    counts = ", ".join(f"{k} {v}" for k, v in summary["by_state"].items() if v)
    print(f"{summary['campaign_id']}: {summary['total']} shots: {counts}")
    for shot in summary["shots"]:
        extra = shot.get("error") or shot.get("reason") or ""
        print(f"  {shot['id']:<10} {shot['state']:<16} fired {shot['fire_count']}x  {extra}".rstrip())
    if summary["needs_decision"]:
        print(f"needs an operator decision: {', '.join(summary['needs_decision'])} "
              f"(hopkinson campaign decide {args.run_folder} SHOT_ID retry|skip)")
    return 0


def decide_command(args: argparse.Namespace) -> int:
    from hopkinson.rig.journal import Journal

    with Journal.open(args.run_folder) as journal:
        status = journal.decide(args.shot_id, args.decision, args.note)
    print(f"{status.shot.id}: {status.state.value} (decision: {args.decision})")
    return 0
