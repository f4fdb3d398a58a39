"""`hopkinson safe`: make the rig safe from any terminal, and confirm it by reading back.

    hopkinson safe [--config PATH | --sim [--sim-config PATH] [--sim-fault NAME ...]]
                   [--stop-holder [--wait-s S]] [-v] [--json]

It runs the sequencer's own SAFE procedure (rig/sequencer/safe.py) on the valve controller
alone (the digitizer and the amplifier play no part in a safe rig, and need not be on): fire
and fill closed, vent open, pump off; then the valves are read back (their real positions
where the controller has limit switches) and re-commanded while wrong, until every one is
right and the reservoir is vented, within timeouts.safe_s. Exit 0 when confirmed, 3 when not
(the line says what is wrong: check the rig by hand).

It takes the rig's lock first (rig/lock.py), like every process that commands the rig, and
feeds the controller's watchdog while it works. It never fights a running shot: when another
process holds the rig (a shot, a campaign, a panel), it commands nothing, names the holder
and exits 2. That process makes the rig safe itself whenever it stops (every signal leads it
to SAFE). `--stop-holder` asks it to: it sends the holder SIGTERM (only a process of this
user, on this PC), waits up to --wait-s for it to finish its SAFE and release the rig, then
takes the lock and confirms the safe state itself. A holder that does not let go in time is
reported (exit 3): the controller's link watchdog vents the rig if that process has died or
hung with its heartbeat; the e-stop is always there.

Signals (Ctrl-C, SIGTERM, SIGHUP) do not interrupt the SAFE procedure: they are noted and
the command finishes its read-back first.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import time
from typing import Any

from hopkinson.rig.cli.main import add_rig_arguments, emit_json, rig_config_path
from hopkinson.rig.errors import EXIT_ABORTED, ConfigError

STOP_MARGIN_S = 15.0  # --wait-s default: the holder's SAFE (timeouts.safe_s) plus this


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `safe` sub-command."""
    p = subparsers.add_parser(
        "safe", help="make the rig safe (fire and fill closed, vent open, pump off) and confirm it by reading back",
        description="Make the rig safe from any terminal and confirm it by reading back. Refuses to command a rig "
                    "another process holds; --stop-holder asks that process to stop (it goes SAFE itself).")
    add_rig_arguments(p)
    p.add_argument("--stop-holder", action="store_true",
                   help="if another process of this user holds the rig, send it SIGTERM, wait for it to go safe "
                        "and let go, then confirm the safe state here")
    p.add_argument("--wait-s", type=float, metavar="S",
                   help=f"how long --stop-holder waits (default: timeouts.safe_s + {STOP_MARGIN_S:g} s)")
    p.add_argument("-v", "--verbose", action="store_true", help="also print every reading")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout (what was read back)")
    p.set_defaults(func=run_safe_command)


def run_safe_command(args: argparse.Namespace) -> int:
    from hopkinson.rig.signals import SignalLatch

    with SignalLatch():  # a signal is noted, never cuts the SAFE procedure short
        return _run_safe(args)


def _run_safe(args: argparse.Namespace) -> int:
    from hopkinson.drivers.errors import InstrumentError
    from hopkinson.rig.cli.output import EventPrinter
    from hopkinson.rig.config import load_rig_config, load_sim_config
    from hopkinson.rig.events import EventBus
    from hopkinson.rig.instruments import make_instrument
    from hopkinson.rig.lock import RigLock, RigLockError, command_line
    from hopkinson.rig.sequencer import State, make_rig_safe
    from hopkinson.rig.sequencer.context import Publisher

    if args.sim_fault and not args.sim:
        raise ConfigError("--sim-fault needs --sim")
    if args.wait_s is not None and not 0 < args.wait_s <= 3600:
        raise ConfigError(f"--wait-s: must be in (0, 3600] s, got {args.wait_s:g}")
    config = load_rig_config(rig_config_path(args))
    with contextlib.ExitStack() as stack:
        if args.sim:
            from hopkinson.rig.sim_session import sim_session

            session = stack.enter_context(sim_session(config, load_sim_config(args.sim_config), args.sim_fault))
            config = session.config
        try:
            lock = RigLock.acquire(config, command_line())
        except RigLockError as exc:
            if not args.stop_holder or exc.holder is None or exc.holder.pid <= 0:
                raise RigLockError(f"{exc}. That process makes the rig safe itself when it stops; "
                                   "`hopkinson safe --stop-holder` asks it to (SIGTERM) and then confirms the safe "
                                   f"state here; `hopkinson status` reads the rig without touching it") from None
            wait_s = args.wait_s if args.wait_s is not None else config.timeouts.safe_s + STOP_MARGIN_S
            lock = _stop_holder(config, exc.holder, wait_s)
        stack.callback(lock.release)
        if lock.reclaimed is not None:
            sys.stderr.write(f"hopkinson: warning: took over the rig lock left by {lock.reclaimed.describe()}, "
                             "which is no longer running\n")
        valves = make_instrument(config, "valve_controller")
        stack.callback(valves.close)
        try:
            valves.connect()
        except InstrumentError as exc:  # nothing confirmed the safe state: exit 3, never "bad input"
            problem = (f"the valve controller cannot be reached ({exc}): check the rig by hand; the controller's "
                       "link watchdog vents it when no heartbeat comes")
            if args.json:
                emit_json({"confirmed": False, "problem": problem, "reservoir_pressure_bar": None,
                           "elapsed_s": 0.0, "valves": {}})
            sys.stderr.write(f"hopkinson: error: SAFE NOT CONFIRMED: {problem}\n")
            return EXIT_ABORTED
        try:
            valves.start_heartbeat()
        except Exception as exc:  # noqa: BLE001 - making safe must not depend on the watchdog
            sys.stderr.write(f"hopkinson: warning: the controller's link watchdog could not be started: {exc}\n")
        bus = EventBus()
        if not args.json:
            bus.subscribe(EventPrinter(verbose=args.verbose))
        events = Publisher(bus)
        events.state = State.SAFE
        result = make_rig_safe(valves, config, events)
        read_back = _read_back(valves)
    report = {"confirmed": result.confirmed, "problem": result.problem,
              "reservoir_pressure_bar": result.reservoir_pressure_bar, "elapsed_s": round(result.elapsed_s, 3),
              "valves": read_back}
    if args.json:
        emit_json(report)
    else:
        for name, value in read_back.items():
            print(f"{name.replace('_', ' '):<22} {value}", flush=True)
    if not result.confirmed:
        sys.stderr.write(f"hopkinson: error: SAFE NOT CONFIRMED: {result.problem}; check the rig by hand\n")
        return EXIT_ABORTED
    if not args.json:
        print(f"rig safe: confirmed by reading back in {result.elapsed_s:.2f} s", flush=True)
    return 0


def _read_back(valves: Any) -> dict[str, Any]:
    """The valves as the controller reports them after SAFE (commanded and, where known, real)."""
    try:
        states = valves.valves()
    except Exception as exc:  # noqa: BLE001 - SAFE's own result already says what failed
        return {"read_back": f"failed: {exc}"}
    word = {True: "open", False: "shut", None: "not reported"}
    out: dict[str, Any] = {}
    for valve in ("fire_valve", "fill_valve", "vent_valve"):
        out[valve] = f"{word[bool(getattr(states, valve))]} (commanded), " \
                     f"{word[getattr(states, f'{valve}_position', None)]} (limit switch)"
    out["vacuum_pump"] = "on" if states.vacuum_pump else "off"
    return out


def _stop_holder(config: Any, holder: Any, wait_s: float) -> Any:
    """SIGTERM the holder, wait for it to let go of the rig, and take the lock."""
    from hopkinson.rig.lock import RigLock, RigLockError, command_line

    if holder.host and holder.host != os.uname().nodename:
        raise RigLockError(f"the rig is held by {holder.describe()} on another PC: stop it there") from None
    try:
        os.kill(holder.pid, signal.SIGTERM)
    except PermissionError:
        raise RigLockError(f"the rig is held by {holder.describe()}, a process of another user: ask them to stop "
                           "it (it goes SAFE itself), or use the e-stop") from None
    except ProcessLookupError:
        pass  # gone meanwhile: its lock is free
    sys.stderr.write(f"hopkinson: sent SIGTERM to pid {holder.pid} ({holder.command}); waiting up to {wait_s:g} s "
                     "for it to make the rig safe and let go\n")
    deadline = time.monotonic() + wait_s
    while True:
        try:
            return RigLock.acquire(config, command_line())
        except RigLockError as exc:
            if time.monotonic() >= deadline:
                raise _HolderDidNotStop(f"pid {holder.pid} still holds the rig after {wait_s:g} s: it may be hung. "
                                        "If its heartbeat stopped, the controller's watchdog vents the rig; "
                                        "otherwise use the e-stop") from exc
            time.sleep(0.1)


class _HolderDidNotStop(ConfigError):
    exit_code = EXIT_ABORTED
