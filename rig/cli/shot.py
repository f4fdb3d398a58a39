"""`hopkinson shot`: fire one calibration shot, store it, analyse it.

    hopkinson shot [--config PATH] [--sim [--sim-config PATH] [--sim-fault NAME ...]
                   [--sim-state-file PATH]] [--pressure-bar P] [--projectile N] [--yes]
                   [--out DIR] [--operator NAME] [--accelerometer-model M]
                   [--accelerometer-serial S] [--sensitivity-v-per-m-s2 S] [--max-order N]
                   [--sample-rate HZ] [--dcm-ratio R] [--dcm-damping Z] [--shot-name NAME] [--json]

--config: the rig configuration (default config/rig.toml; with --sim config/rig-sim.toml, of
which only limits, timeouts and analysis constants are used: the addresses are those of an
in-process simulated rig started on free ports from --sim-config, default config/sim.toml).

Confirmation. The shot is fired only with --yes, or when standard input is a terminal and the
operator types "yes" at the prompt shown once the rig is armed (60 s to answer). Otherwise the
sequencer runs up to ARM, reports, goes SAFE, and the command exits 3 saying the shot was not
confirmed.

Output: the state changes and progress as lines on stdout (or, with --json, one JSON object:
the outcome, plus the simulator's final state with --sim). Exit codes: 0 done (also when the
analysis failed: the shot is recorded, the analysis error is printed on stderr); 2 bad input
or configuration (nothing was moved); 3 the shot was aborted to the safe state (one line on
stderr: which state, which instrument, why); 130 Ctrl-C, after SAFE has run (Ctrl-C asks the
sequencer to abort; it never interrupts SAFE).
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from hopkinson.rig.cli.main import add_rig_arguments, emit_json, rig_config_path, signals_abort
from hopkinson.rig.errors import ConfigError

PROMPT_TIMEOUT_S = 60.0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `shot` sub-command."""
    p = subparsers.add_parser(
        "shot", help="fire one calibration shot (CHECK..FIRE..ANALYSE), store and analyse it",
        description="Fire one shot: check, evacuate, charge, arm, fire, capture, make safe, store the "
                    "raw data, analyse. Fires only with --yes or a 'yes' typed at the prompt.")
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
    p.add_argument("--sensitivity-v-per-m-s2", type=float, help="nominal sensitivity (default: config [analysis])")
    p.add_argument("--max-order", type=int, help="highest model order tried by the identification")
    p.add_argument("--sample-rate", type=float, dest="sample_rate_hz", help="analysis sample rate, Hz")
    p.add_argument("--dcm-ratio", type=float, help="DCM response-time ratio r")
    p.add_argument("--dcm-damping", type=float, help="DCM damping of the new poles")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout (the outcome)")
    p.set_defaults(func=run_shot_command)


def run_shot_command(args: argparse.Namespace) -> int:
    # Imported here: the drivers (pymodbus, pyvisa, pyserial) load only when a shot runs.
    from hopkinson.rig.config import load_rig_config, load_sim_config
    from hopkinson.rig.events import EventBus, RigEvent
    from hopkinson.rig.instruments import open_instruments
    from hopkinson.rig.sequencer import FireAuthorisation, Sequencer
    from hopkinson.rig.shot import ShotRequest

    if not args.sim and (args.sim_fault or args.sim_state_file):
        raise ConfigError("--sim-fault and --sim-state-file need --sim")
    config = load_rig_config(rig_config_path(args))
    _make_out_dir(args.out)
    interactive = not args.yes and sys.stdin is not None and sys.stdin.isatty()
    request = ShotRequest(
        pressure_bar=args.pressure_bar, projectile=args.projectile, operator=args.operator,
        accelerometer_model=args.accelerometer_model, accelerometer_serial=args.accelerometer_serial,
        sensitivity_v_per_m_s2=args.sensitivity_v_per_m_s2, max_order=args.max_order,
        sample_rate_hz=args.sample_rate_hz, dcm_ratio=args.dcm_ratio, dcm_damping=args.dcm_damping,
        out_dir=args.out, shot_name=args.shot_name,
        # Without --yes and without a terminal nobody can confirm: do not wait in ARM.
        confirm_timeout_s=None if args.yes else (PROMPT_TIMEOUT_S if interactive else 0.0),
    )
    request.check(config)  # bad input: exit 2 before anything starts
    authorisation = FireAuthorisation.pre_given() if args.yes else FireAuthorisation()

    bus = EventBus()
    if not args.json:
        bus.subscribe(_print_event)
    sim_state: dict[str, Any] | None = None
    interrupted = threading.Event()
    with contextlib.ExitStack() as stack:
        truth = None
        if args.sim:
            from hopkinson.rig.sim_session import sim_session

            session = stack.enter_context(sim_session(config, load_sim_config(args.sim_config), args.sim_fault,
                                                      args.sim_state_file))
            config, truth = session.config, session.simulated_truth
        instruments = stack.enter_context(open_instruments(config, truth))
        sequencer = Sequencer(instruments, config, bus)

        def on_event(event: RigEvent) -> None:
            if event.kind == "state" and interrupted.is_set():
                sequencer.abort("interrupted (Ctrl-C)")  # a Ctrl-C that came before the shot began
            if interactive and event.kind == "progress" and event.data.get("awaiting_confirmation"):
                threading.Thread(target=_prompt, args=(request, authorisation, sequencer),
                                 name="shot-prompt", daemon=True).start()

        bus.subscribe(on_event)
        with signals_abort(sequencer.abort, interrupted, {signal.SIGINT: "interrupted (Ctrl-C)"}):
            outcome = sequencer.run_shot(request, authorisation)
        if args.sim:
            sim_state = session.state()
    if interrupted.is_set():
        raise KeyboardInterrupt
    if args.json:
        out = outcome.to_dict()
        if sim_state is not None:
            out["sim_state"] = sim_state
        emit_json(out)
    elif outcome.shot_path is not None:
        print(f"shot file: {outcome.shot_path}", flush=True)
        if outcome.results:
            from hopkinson.rig.campaign import (
                result_line,  # the campaign's one-line summary of the figures
            )

            print(f"results:   {result_line(outcome.results)}", flush=True)
    for warning in outcome.warnings:
        sys.stderr.write(f"hopkinson: warning: {warning}\n")
    if outcome.done and outcome.analysis_error:
        sys.stderr.write(f"hopkinson: warning: the shot is recorded but its {outcome.analysis_error}\n"
                         if outcome.analysis_error.startswith("analysis")
                         else f"hopkinson: warning: {outcome.analysis_error}\n")
    outcome.raise_for_outcome()
    return 0


def _make_out_dir(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out: cannot create the folder {out}: {exc.strerror or exc}") from None


def _print_event(event: Any) -> None:
    if event.kind in ("state", "progress", "log", "error"):
        marker = {"error": "! ", "log": "  "}.get(event.kind, "")
        sys.stdout.write(f"{event.state:<9} {marker}{event.message}\n")  # one write: one whole line
        sys.stdout.flush()


def _prompt(request: Any, authorisation: Any, sequencer: Any) -> None:
    sys.stderr.write(f"Armed at {request.pressure_bar:g} bar, projectile No. {request.projectile}. "
                     f"Type yes to FIRE (anything else aborts): ")
    sys.stderr.flush()
    answer = sys.stdin.readline()
    if answer.strip().lower() == "yes":
        authorisation.give()
    else:
        sequencer.abort("the operator did not confirm the shot")
