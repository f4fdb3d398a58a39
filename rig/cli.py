"""The `hopkinson` command: one sub-command per module in COMMAND_MODULES.

Each command module has `register(subparsers)`, which adds its parser(s) and sets
`func(args) -> int` as the default. Known errors become one line on stderr and an exit
code (2: bad input or configuration; 3: shot aborted to the safe state); no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from typing import Any

# Modules that provide sub-commands, in the order `hopkinson --help` lists them. Each keeps
# its heavy imports (Qt, pymodbus, matplotlib) inside the functions that need them.
COMMAND_MODULES = [
    "rig.commands_shot",
    "rig.commands_campaign",
    "rig.commands_panel",
    "rig.commands_sim",
    "rig.commands_identify",
    "rig.commands_dcm",
    "rig.commands_reduce",
    "rig.commands_report",
    "rig.commands_demo",
]


def _known_errors() -> tuple[type[BaseException], ...]:
    from analysis.errors import AnalysisError
    from rig.errors import ConfigError, ShotAborted

    errors: list[type[BaseException]] = [AnalysisError, ConfigError, ShotAborted]
    try:
        from drivers.errors import InstrumentError

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
