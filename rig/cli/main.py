"""The `hopkinson` command: one sub-command per module in COMMAND_MODULES.

Each command module has `register(subparsers)`, which adds its parser(s) and sets
`func(args) -> int` as the default. Known errors become one line on stderr and an exit
code (2: bad input or configuration, an output that would destroy an input, a file that
cannot be read or written; 3: shot aborted to the safe state; every code: rig/errors.py
EXIT_CODES, docs/exit-codes.md, `hopkinson --help`); no traceback.

Signals. The commands that drive the rig (shot, campaign run, panel, safe) catch SIGINT,
SIGTERM and SIGHUP themselves (rig/signals.py: every way out goes SAFE, exit code 3). Every
other command ends cleanly on SIGTERM and SIGHUP (the `with` blocks unwind, so an atomic write
in progress removes its temporary file) with exit code 128 + the signal's number, and on
Ctrl-C with 130.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import sys
from pathlib import Path
from typing import Any

# The analysis is single-threaded by design: its matrices are tall and thin (bins × parameters),
# where BLAS threads gain nothing, and on a busy machine they make each factorisation wait for
# cores at random (`hopkinson identify` of benchmarks/bench_identify.py's 2·10⁵-sample record,
# two other processes busy: its 550 QRs 0.1 s on one thread, 18 s threaded). Set before NumPy
# loads (nothing above imports it); a value the user set is kept.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
for _variable in BLAS_THREAD_VARIABLES:
    os.environ.setdefault(_variable, "1")

from hopkinson.rig.config_paths import (  # noqa: E402 - after the BLAS variables above
    DEFAULT_SIM_CONFIG,
    DEFAULT_SIM_RIG_CONFIG,
    default_rig_config,
)

# Modules that provide sub-commands, in the order `hopkinson --help` lists them. Each keeps
# its heavy imports (Qt, pymodbus, matplotlib) inside the functions that need them.
COMMAND_MODULES = [
    "hopkinson.rig.cli.shot",
    "hopkinson.rig.cli.campaign",
    "hopkinson.rig.cli.panel",
    "hopkinson.rig.cli.safe",
    "hopkinson.rig.cli.sim",
    "hopkinson.rig.cli.probe",
    "hopkinson.rig.cli.identify",
    "hopkinson.rig.cli.analyse",
    "hopkinson.rig.cli.dcm",
    "hopkinson.rig.cli.compare_sine",
    "hopkinson.rig.cli.plan_shot",
    "hopkinson.rig.cli.reduce",
    "hopkinson.rig.cli.report",
    "hopkinson.rig.cli.lab",
    "hopkinson.rig.cli.demo",
    "hopkinson.rig.cli.config",
]

# Each module registers the command of its own name (`_` as `-`); these register one more.
ALSO_REGISTERED_BY = {"status": "hopkinson.rig.cli.sim", "compensate": "hopkinson.rig.cli.dcm"}


def command_module(command: str | None) -> str | None:
    """The module that registers sub-command `command` (None: no such command)."""
    if command is None:
        return None
    own = f"hopkinson.rig.cli.{command.replace('-', '_')}"
    return own if own in COMMAND_MODULES else ALSO_REGISTERED_BY.get(command)


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
    from hopkinson.fileio import UnsafeOutputError
    from hopkinson.lab.errors import LabError
    from hopkinson.rig.errors import ConfigError, ShotAborted

    errors: list[type[BaseException]] = [AnalysisError, ConfigError, LabError, ShotAborted, UnsafeOutputError]
    try:
        from hopkinson.drivers.errors import InstrumentError

        errors.append(InstrumentError)
    except ImportError:
        pass
    return tuple(errors)


class _VersionAction(argparse.Action):
    """--version: the installed version, looked up only when asked."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS,
                 default: str = argparse.SUPPRESS, help: str = "show the program's version and exit") -> None:
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        from hopkinson import __version__

        sys.stdout.write(f"{parser.prog} {__version__}\n")
        parser.exit()


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser with every registered sub-command, or, given a known `command`, with
    only the commands of the module that registers it: `hopkinson identify` then imports and builds
    no other command's parser (`hopkinson identify --help` 88 ms instead of 110; the command line
    parses and reads the same: tests/rig/test_cli_registry.py)."""
    from hopkinson.rig.errors import exit_codes_help

    parser = argparse.ArgumentParser(
        prog="hopkinson",
        description="Hopkinson-bar shock calibration of high-g accelerometers.",
        epilog=exit_codes_help(), formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    module = command_module(command)
    for name in COMMAND_MODULES if module is None else [module]:
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


# Every option that names a file a command writes (a folder option such as --out is not one).
WRITE_FLAGS = {"output": "-o", "log_file": "--log-file", "sim_state_file": "--sim-state-file",
               "sim_fire_log": "--sim-fire-log", "plot": "--plot", "screenshot": "--screenshot"}


def check_write_flags(args: argparse.Namespace) -> None:
    """No write flag may name a file the command reads (its --config, its default rig
    configuration, a plan, a record, a model ...), another write flag's file or a shot file:
    refused before anything moves (hopkinson.fileio.check_writes)."""
    from hopkinson.fileio import check_writes

    def paths(value: Any) -> list[Any]:
        values = value if isinstance(value, list | tuple) else [value]
        return [v for v in values if isinstance(v, str | Path) and str(v)]

    outputs = [(WRITE_FLAGS[name], p) for name in WRITE_FLAGS for p in paths(getattr(args, name, None))]
    if not outputs:
        return
    inputs = [p for name, value in vars(args).items() if name not in WRITE_FLAGS
              for p in paths(value) if _is_file(p)]
    if hasattr(args, "sim") and hasattr(args, "config"):
        inputs.append(rig_config_path(args))  # read even when not named
    check_writes(outputs, inputs)


def _is_file(value: Any) -> bool:
    """Whether an argument names an existing file (a text no file can be named, e.g. longer
    than the system's name limit, is not one)."""
    try:
        return Path(value).is_file()
    except (OSError, ValueError):
        return False


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `hopkinson` console command."""
    from hopkinson.rig.errors import Interrupted
    from hopkinson.rig.signals import exit_cleanly_on_termination

    words = sys.argv[1:] if argv is None else argv
    parser = build_parser(next((w for w in words if not w.startswith("-")), None))
    args = parser.parse_args(words)
    known = _known_errors()
    try:
        with exit_cleanly_on_termination():
            check_write_flags(args)
            return int(args.func(args) or 0)
    except known as exc:
        return fail(str(exc), getattr(exc, "exit_code", 2))
    except BrokenPipeError:  # the reader went away (`| head`): quietly, as a pipe writer does
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 128 + 13  # SIGPIPE
    except OSError as exc:  # a missing or unreadable input, an unwritable output, a folder for a file
        return fail(os_error_text(exc))
    except Interrupted as exc:
        return fail(str(exc), exc.exit_code)
    except KeyboardInterrupt:
        return fail("interrupted", 130)


def os_error_text(exc: OSError) -> str:
    """One line for an operating-system error: the file, and what is wrong with it."""
    if isinstance(exc, FileNotFoundError):
        return f"{exc.filename}: no such file"
    what = exc.strerror or str(exc)
    if exc.filename is not None:
        target = f"{exc.filename} -> {exc.filename2}" if exc.filename2 is not None else str(exc.filename)
        return f"{target}: {what}"
    return what


if __name__ == "__main__":
    sys.exit(main())
