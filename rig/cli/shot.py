"""`hopkinson shot`: fire one calibration shot, store it, analyse it.

    hopkinson shot [--config PATH] [--sim [--sim-config PATH] [--sim-fault NAME ...]
                   [--sim-state-file PATH]] [--pressure-bar P] [--projectile N] [--yes]
                   [--out DIR] [--operator NAME] [--accelerometer-model M]
                   [--accelerometer-serial S] [--accelerometer-2-model M --accelerometer-2-serial S]
                   [--sensitivity-v-per-m-s2 S] [--max-order N]
                   [--sample-rate HZ] [--dcm-ratio auto|R] [--dcm-damping Z] [--draws N]
                   [--no-uncertainty] [--shot-name NAME]
                   [-v] [--log-file PATH] [--trace] [--json | --json-events]

--config: the rig configuration (default config/rig.toml; with --sim config/rig-sim.toml, of
which only limits, timeouts and analysis constants are used: the addresses are those of an
in-process simulated rig started on free ports from --sim-config, default config/sim.toml).

Before anything moves: the request and every analysis option are checked, the shot file's
name is fixed (an existing shot file is refused) and the rig's lock is taken (rig/lock.py: a
rig held by another shot, campaign or panel is refused at once, exit 2, naming the holder).
While the command controls the rig it feeds the controller's link watchdog (rig/control.py).

Confirmation. The shot is fired only with --yes, or when standard input is a terminal and the
operator types "yes" at the prompt shown once the rig is armed (60 s to answer; unanswered, the
sequencer goes SAFE and the command exits 3). Without --yes and without a terminal nobody can
confirm: the shot is refused before anything moves (exit 2), as `campaign run` refuses a plan
without authorisation.

Signals. SIGINT (Ctrl-C), SIGTERM and SIGHUP, whenever they come, abort the shot: the
sequencer goes SAFE (fire and fill closed, reservoir vented, read back) and the command exits
3. One that comes after the shot (during its analysis or later) runs SAFE again before the
exit. A signal never interrupts SAFE itself.

Output: the state changes and progress as lines on stdout, each with its UTC time (-v adds the
readings and identities); with --json one JSON object at the end (the outcome, plus the
simulator's final state with --sim); with --json-events every event as one JSON line as it
happens (the last one is the outcome). The shot's JSON-lines log is written beside the shot
file (<name>.log.jsonl, rig/logbook.py), also for a shot aborted before anything was recorded;
--log-file writes a copy elsewhere; --trace adds every instrument command and reply to the logs.

Exit codes (docs/exit-codes.md, `hopkinson shot --help`): 0 fired, recorded and analysed; 2 bad
input or configuration, or the rig held by another process (nothing was moved); 3 the shot was
aborted to the safe state, ended in FAULT, or was interrupted by a signal (one line on stderr:
which state, which instrument, why); 4 the shot is recorded but its analysis failed (one line
on stderr; the raw shot is kept); 5 the shot is done but its lab record is in neither the
database nor the spool (`hopkinson lab import` it). The --json object's `exit_code` is always
the exit code.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import threading
from pathlib import Path
from typing import Any

from hopkinson.rig.cli.main import add_rig_arguments, emit_json, rig_config_path
from hopkinson.rig.errors import EXIT_ABORTED, EXIT_DONE, ConfigError, exit_codes_help

PROMPT_TIMEOUT_S = 60.0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `shot` sub-command."""
    p = subparsers.add_parser(
        "shot", help="fire one calibration shot (CHECK..FIRE..ANALYSE), store and analyse it",
        description="Fire one shot: check, evacuate, charge, arm, fire, capture, make safe, store the "
                    "raw data, analyse. Fires only with --yes or a 'yes' typed at the prompt.",
        epilog=exit_codes_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    add_rig_arguments(p)
    p.add_argument("--sim-state-file", type=Path, metavar="PATH",
                   help="with --sim: write the simulator's final state as JSON here (also on failures)")
    p.add_argument("--pressure-bar", type=float, default=2.0, help="reservoir pressure, gauge bar (default %(default)s)")
    p.add_argument("--projectile", type=int, default=3, choices=(1, 2, 3), help="projectile No. (default %(default)s)")
    p.add_argument("--yes", action="store_true", help="confirm the shot: fire without asking")
    p.add_argument("--out", type=Path, default=Path("shots"), help="folder for the shot file (default %(default)s)")
    p.add_argument("--shot-name", help="file name of the shot without .h5 (default: shot-<UTC time>-<id>)")
    p.add_argument("--operator", default="", help="who fires the shot")
    p.add_argument("--accelerometer-model", default="", help="model of the accelerometer under test")
    p.add_argument("--accelerometer-serial", default="", help="serial number of the accelerometer under test")
    p.add_argument("--accelerometer-2-model", metavar="M",
                   help="model of a second accelerometer, recorded on the rig's response_2 channel")
    p.add_argument("--accelerometer-2-serial", metavar="S", help="its serial number")
    p.add_argument("--sensitivity-v-per-m-s2", type=float, help="nominal sensitivity (default: config [analysis])")
    p.add_argument("--max-order", type=int, help="highest model order tried by the identification")
    p.add_argument("--sample-rate", type=float, dest="sample_rate_hz", help="analysis sample rate, Hz")
    p.add_argument("--dcm-ratio", default="auto", metavar="auto|R",
                   help="DCM response-time ratio r (> 0), or 'auto' (default): sized to the shot's pulse (or the "
                        "±5 %% band widened [analysis] dcm_widening times) within dcm_noise_gain_limit (rig config)")
    p.add_argument("--dcm-damping", type=float, help="DCM damping of the new poles")
    p.add_argument("--draws", type=int, help="Monte Carlo draws of the uncertainty (default: the analysis' own)")
    p.add_argument("--no-uncertainty", dest="uncertainty", action="store_false", default=None,
                   help="no Monte Carlo uncertainty of the key figures (faster; the figures carry none)")
    add_log_arguments(p)
    p.set_defaults(func=run_shot_command)


def add_log_arguments(p: argparse.ArgumentParser) -> None:
    """-v, --log-file, --trace, and --json | --json-events: shared by the commands that drive the rig."""
    out = p.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="one JSON object on stdout at the end (the outcome)")
    out.add_argument("--json-events", action="store_true",
                     help="every event as one JSON line on stdout as it happens (for scripts)")
    p.add_argument("-v", "--verbose", action="store_true", help="also print the readings and instrument identities")
    p.add_argument("--log-file", type=Path, metavar="PATH",
                   help="also write the JSON-lines log of every event here (appended)")
    p.add_argument("--trace", action="store_true",
                   help="record every instrument command and reply in the logs (binary blocks summarised)")


def run_shot_command(args: argparse.Namespace) -> int:
    from hopkinson.rig.signals import SignalLatch

    with SignalLatch() as latch:  # from here on, every signal goes SAFE (exit 3)
        return _run_shot(args, latch)


def _run_shot(args: argparse.Namespace, latch: Any) -> int:
    # Imported here: the drivers (pymodbus, pyvisa, pyserial) load only when a shot runs.
    from hopkinson.analysis.options import AnalysisOverrides
    from hopkinson.rig.cli.dcm import number_or_word
    from hopkinson.rig.config import load_rig_config, load_sim_config
    from hopkinson.rig.control import controlled_rig, run_shot_under_signals
    from hopkinson.rig.events import AwaitingConfirmation, EventBus
    from hopkinson.rig.instruments import with_sim_channels
    from hopkinson.rig.lab_record import attach_recorder
    from hopkinson.rig.lock import command_line
    from hopkinson.rig.sequencer import FireAuthorisation, Sequencer
    from hopkinson.rig.shot import ShotRequest, generated_shot_name, second_accelerometer

    if not args.sim and (args.sim_fault or args.sim_state_file):
        raise ConfigError("--sim-fault and --sim-state-file need --sim")
    interactive = not args.yes and sys.stdin is not None and sys.stdin.isatty()
    if not args.yes and not interactive:
        raise ConfigError("nothing can confirm this shot: standard input is not a terminal and --yes was not "
                          "given (give --yes to fire without asking); nothing was moved")
    config = load_rig_config(rig_config_path(args))
    _make_out_dir(args.out)
    request = ShotRequest(
        pressure_bar=args.pressure_bar, projectile=args.projectile, operator=args.operator,
        accelerometer_model=args.accelerometer_model, accelerometer_serial=args.accelerometer_serial,
        sensor_identities=second_accelerometer(args.accelerometer_2_model, args.accelerometer_2_serial),
        analysis=AnalysisOverrides(
            sensitivity_v_per_m_s2=args.sensitivity_v_per_m_s2, max_order=args.max_order,
            sample_rate_hz=args.sample_rate_hz, dcm_damping=args.dcm_damping,
            dcm_ratio=number_or_word(args.dcm_ratio, "--dcm-ratio", {"auto": None}, "a positive number"),
            uncertainty=args.uncertainty, draws=args.draws),
        out_dir=args.out, shot_name=args.shot_name or generated_shot_name(),
        confirm_timeout_s=None if args.yes else PROMPT_TIMEOUT_S,
    )
    sim_config = load_sim_config(args.sim_config) if args.sim else None
    # bad input (the analysis options, a sensor on a channel the rig lacks): exit 2 before anything starts
    request.check(with_sim_channels(config, sim_config) if sim_config is not None else config)
    if request.shot_path().exists():
        raise ConfigError(f"--shot-name: {request.shot_path()} exists already: a shot file is never written over")
    authorisation = FireAuthorisation.pre_given() if args.yes else FireAuthorisation()

    bus = EventBus()
    sim_state: dict[str, Any] | None = None
    with contextlib.ExitStack() as stack:
        subscribe_outputs(stack, bus, args, what=f"shot {request.shot_path().name}")
        recorder = attach_recorder(bus, config, stack)  # the lab's record (hopkinson.lab)
        truth = None
        if args.sim:
            from hopkinson.rig.sim_session import sim_session

            session = stack.enter_context(sim_session(config, sim_config, args.sim_fault,
                                                      args.sim_state_file))
            config, truth = session.config, session.simulated_truth
        control = stack.enter_context(controlled_rig(config, command_line(), truth))
        report_reclaimed(control)
        sequencer = Sequencer(control.instruments, config, bus, trace=args.trace)
        if interactive:
            def on_event(event: Any) -> None:
                if isinstance(event, AwaitingConfirmation):
                    threading.Thread(target=_prompt, args=(request, authorisation, sequencer),
                                     name="shot-prompt", daemon=True).start()
            bus.subscribe(on_event)
        shot = run_shot_under_signals(sequencer, request, authorisation, latch)
        if latch.received is not None and shot.outcome.done:  # after the shot ended: the log says so too
            from hopkinson.rig.events import RigError

            bus.publish(RigError(state=shot.outcome.final_state, source="operator",
                                 message=f"{latch.reason} after the shot ended: the command exits {EXIT_ABORTED}"))
        if args.sim:
            sim_state = session.state()
    tell_unshown_warnings(args, recorder.messages)  # the lab record's, when no event line showed them
    kept = not_recorded_exit(recorder, EXIT_DONE) == EXIT_DONE  # (says which record is lost)
    return _report(args, shot.outcome, sim_state, latch, shot.safe_again, record_lost=not kept)


def events_shown(args: argparse.Namespace) -> bool:
    """Whether the command printed its events as lines for people (not --json, --json-events)."""
    return not (getattr(args, "json", False) or getattr(args, "json_events", False))


def tell_unshown_warnings(args: argparse.Namespace, warnings: Any) -> None:
    """Warnings on stderr, once each, when no event line has shown them (--json: stdout is one
    object; --json-events: the events are for a script). With event lines they were told there."""
    if not events_shown(args):
        for warning in dict.fromkeys(warnings):
            sys.stderr.write(f"hopkinson: warning: {warning}\n")


def not_recorded_exit(recorder: Any, code: int) -> int:
    """A shot whose lab record is in neither the database nor the spool never exits 0."""
    from hopkinson.rig.lab_record import EXIT_NOT_RECORDED

    for path in recorder.not_kept:
        sys.stderr.write(f"hopkinson: error: the lab record of {path} is in neither the database nor the spool; "
                         f"the shot file is kept: run `hopkinson lab import {path}`\n")
    return EXIT_NOT_RECORDED if recorder.not_kept and code == 0 else code


def subscribe_outputs(stack: contextlib.ExitStack, bus: Any, args: argparse.Namespace, what: str,
                      lines: bool = True) -> None:
    """The command's outputs on the bus: event lines (unless `lines` is False: a campaign
    prints its own) or JSON lines, and the --log-file copy."""
    from hopkinson.rig.cli.output import EventPrinter, JsonEventStream
    from hopkinson.rig.lock import command_line
    from hopkinson.rig.logbook import Logbook

    if getattr(args, "json_events", False):
        bus.subscribe(JsonEventStream())
    elif lines and not getattr(args, "json", False):
        bus.subscribe(EventPrinter(verbose=args.verbose))
    if args.log_file is not None:
        try:
            logbook = Logbook(args.log_file, command=command_line(), what=what)
        except OSError as exc:
            raise ConfigError(f"--log-file: {args.log_file}: cannot be written ({exc.strerror or exc})") from None
        stack.callback(logbook.close)
        logbook.attach(bus)


def report_reclaimed(control: Any) -> None:
    if control.reclaimed is not None:
        sys.stderr.write(f"hopkinson: warning: took over the rig lock left by {control.reclaimed.describe()}, "
                         "which is no longer running\n")


def _verdict_line(shot_path: Any) -> str | None:
    """'ACCEPT — fit … · band …' for the stored shot (rig.shot_verdict), None when unreadable."""
    from hopkinson.rig.shot_verdict import shot_judgement
    from hopkinson.rig.shotfile import ShotFileError, read_shot

    try:
        return shot_judgement(read_shot(shot_path, load_raw=False)).verdict.line()
    except (ShotFileError, OSError):
        return None


def _report(args: argparse.Namespace, outcome: Any, sim_state: dict[str, Any] | None, latch: Any,
            safe_again: tuple[bool, str | None] | None, record_lost: bool = False) -> int:
    """Print the outcome; the exit code (docs/exit-codes.md), which the --json object carries too."""
    from hopkinson.rig.lab_record import EXIT_NOT_RECORDED

    exit_code = EXIT_ABORTED if latch.received is not None else \
        EXIT_NOT_RECORDED if record_lost and outcome.exit_code == EXIT_DONE else outcome.exit_code
    if args.json:
        out = outcome.to_dict()
        if sim_state is not None:
            out["sim_state"] = sim_state
        if latch.received is not None:
            out["interrupted"] = latch.reason
        out["exit_code"] = exit_code  # as the process exits
        emit_json(out)
    elif outcome.shot_path is not None and not args.json_events:
        print(f"shot file: {outcome.shot_path}", flush=True)
        if outcome.log_path is not None:
            print(f"log:       {outcome.log_path}", flush=True)
        if outcome.results:
            from hopkinson.rig.campaign_results import (
                result_line,  # the campaign's one-line summary of the figures
            )

            print(f"results:   {result_line(outcome.results)}", flush=True)
            verdict = _verdict_line(outcome.shot_path)
            if verdict:
                print(f"verdict:   {verdict}", flush=True)
            for role, sensor in (outcome.results.get("sensors") or {}).items():  # further sensors, by role
                text = result_line(sensor) if "model" in sensor else f"not analysed: {sensor.get('error')}"
                print(f"{role}: {text}", flush=True)
    tell_unshown_warnings(args, outcome.warnings)  # the sequencer's (RigWarning events too)
    if outcome.done and outcome.analysis_error and latch.received is None:
        what = outcome.analysis_error if outcome.analysis_error.startswith("analysis") else \
            f"analysis failed: {outcome.analysis_error}"
        sys.stderr.write(f"hopkinson: error: the shot is recorded in {outcome.shot_path} but its {what} "
                         f"(exit {outcome.exit_code}: `hopkinson analyse` it again once the cause is fixed)\n")
    if latch.received is not None:
        before = "the shot was recorded before it; " if outcome.done else (f"{outcome.error}; " if outcome.error else "")
        if safe_again is None and not outcome.done:
            line = outcome.error or f"shot ended in {outcome.final_state}"
        elif safe_again is None:  # the signal came once the shot had ended: nothing moved since
            line = "it came after the shot had ended with the rig confirmed safe; nothing was moved after that"
        elif not safe_again[0]:
            line = f"{'' if outcome.done else before}SAFE NOT CONFIRMED: {safe_again[1]}; check the rig by hand"
        else:
            line = f"{before}SAFE ran again and was confirmed"
        sys.stderr.write(f"hopkinson: error: {latch.reason}: {line}\n")
        return EXIT_ABORTED
    outcome.raise_for_outcome()
    return exit_code  # 0; 4: recorded, its analysis failed; 5: done, its lab record lost


def _make_out_dir(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out: cannot create the folder {out}: {exc.strerror or exc}") from None


def _prompt(request: Any, authorisation: Any, sequencer: Any) -> None:
    sys.stderr.write(f"Armed at {request.pressure_bar:g} bar, projectile No. {request.projectile}. "
                     f"Type yes to FIRE (anything else aborts): ")
    sys.stderr.flush()
    answer = sys.stdin.readline()
    if answer.strip().lower() == "yes":
        authorisation.give()
    else:
        sequencer.abort("the operator did not confirm the shot")
