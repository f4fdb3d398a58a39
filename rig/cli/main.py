"""The `hopkinson` command: one sub-command per module in COMMAND_MODULES.

Each command module has `register(subparsers)`, which adds its parser(s) and sets
`func(args) -> int` as the default. Known errors become one line on stderr and an exit
code (2: bad input or configuration; 3: shot aborted to the safe state); no traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from hopkinson.rig.config_paths import (
    DEFAULT_SIM_CONFIG,
    DEFAULT_SIM_RIG_CONFIG,
    default_rig_config,
)

from hopkinson import __version__

# Modules that provide sub-commands, in the order `hopkinson --help` lists them. Each keeps
# its heavy imports (Qt, pymodbus, matplotlib) inside the functions that need them.
COMMAND_MODULES = [
    "hopkinson.rig.cli.shot",
    "hopkinson.rig.cli.campaign",
    "hopkinson.rig.cli.panel",
    "hopkinson.rig.cli.sim",
    "hopkinson.rig.cli.identify",
    "hopkinson.rig.cli.dcm",
    "hopkinson.rig.cli.reduce",
    "hopkinson.rig.cli.report",
    "hopkinson.rig.cli.demo",
]

# The shared rig options live here, not in rig.config: building the parser must not load the
# drivers (pymodbus) that the configuration's register maps come from.
DEFAULT_RIG_CONFIG = default_rig_config()


def add_rig_arguments(parser: argparse.ArgumentParser) -> None:
    """The options every rig command shares: --config, --sim, --sim-config, --sim-fault."""
    parser.add_argument("--config", type=Path, help=f"rig TOML (default {DEFAULT_RIG_CONFIG}; with --sim "
                                                    f"{DEFAULT_SIM_RIG_CONFIG})")
    parser.add_argument("--sim", action="store_true", help="run against an in-process simulated rig")
    parser.add_argument("--sim-config", type=Path, default=DEFAULT_SIM_CONFIG,
                        help="simulator TOML for --sim (default %(default)s)")
    parser.add_argument("--sim-fault", action="append", default=[], metavar="NAME",
                        help="inject a simulator fault (repeatable; `hopkinson sim --list-faults`)")


def rig_config_path(args: argparse.Namespace) -> Path:
    """The rig TOML a command uses: --config, else the simulated or the real rig's default."""
    return args.config or (DEFAULT_SIM_RIG_CONFIG if args.sim else DEFAULT_RIG_CONFIG)


def _known_errors() -> tuple[type[BaseException], ...]:
    from hopkinson.analysis.errors import AnalysisError
    from hopkinson.rig.errors import ConfigError, ShotAborted

    errors: list[type[BaseException]] = [AnalysisError, ConfigError, ShotAborted]
    try:
        from hopkinson.drivers.errors import InstrumentError

        errors.append(InstrumentError)
    except ImportError:
        pass
    return tuple(errors)


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every registered sub-command."""
    parser = argparse.ArgumentParser(
        prog="hopkinson",
        description="Hopkinson-bar shock calibration of high-g accelerometers.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def emit_json(obj: Any) -> None:
    """Print one JSON object on stdout (the `--json` contract of every command)."""
    json.dump(obj, sys.stdout, indent=None, separators=(",", ":"), allow_nan=False)
    sys.stdout.write("\n")
    sys.stdout.flush()


def fail(message: str, exit_code: int = 2) -> int:
    """Write one clear line on stderr and return the exit code."""
    sys.stderr.write(f"hopkinson: error: {message}\n")
    return exit_code


@contextlib.contextmanager
def signals_abort(abort: Callable[[str], None], interrupted: threading.Event,
                  reasons: dict[signal.Signals, str]) -> Iterator[None]:
    """While the block runs, each signal in `reasons` calls `abort(reason)` (the shot goes SAFE)
    instead of raising KeyboardInterrupt at a random point, and sets `interrupted`; the caller
    reports the interruption once the block is done. Only in the main thread (signal handlers).

    The handler only notes the signal: it runs in the main thread between two bytecodes, where
    taking a lock the interrupted code holds would deadlock and printing would re-enter the
    stream. A watcher thread calls `abort` (again every 20 ms: an abort asked for before the
    sequencer left IDLE is a no-op; `abort` must be idempotent).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    hit: list[signal.Signals] = []
    done = threading.Event()

    def handler(signum: int, _frame: object) -> None:
        hit.append(signal.Signals(signum))

    def watch() -> None:
        while not done.wait(0.02):
            if hit:
                interrupted.set()
                abort(reasons[hit[0]])

    previous = {sig: signal.signal(sig, handler) for sig in reasons}
    watcher = threading.Thread(target=watch, name="signals-abort", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
        done.set()
        watcher.join()
        if hit:
            interrupted.set()


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `hopkinson` console command."""
    parser = build_parser()
    args = parser.parse_args(argv)
    known = _known_errors()
    try:
        return int(args.func(args) or 0)
    except known as exc:
        return fail(str(exc), getattr(exc, "exit_code", 2))
    except FileNotFoundError as exc:
        return fail(f"{exc.filename}: no such file")
    except KeyboardInterrupt:
        return fail("interrupted", 130)


if __name__ == "__main__":
    sys.exit(main())
