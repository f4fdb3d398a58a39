"""`hopkinson panel`: the technician's Qt panel (ui/app.py).

    hopkinson panel [--config PATH | --sim [--sim-config PATH] [--sim-fault NAME ...]]
                    [--out DIR] [--runs DIR] [--demo-shot] [--screenshot PATH]

The panel controls the rig like a shot does (ui/worker.py's RigLink): it takes the rig's lock
before connecting (a rig held by a shot, a campaign or another panel is refused, exit 2, naming
the holder), feeds the controller's link watchdog while connected, and on SIGINT, SIGTERM or
SIGHUP aborts what runs, runs SAFE (confirmed by reading back), closes and exits 3.

The ui package is imported inside the command's function only: rig never imports ui at module
level (ui imports rig, not the other way round), and the other commands never load Qt.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hopkinson.rig.cli.main import add_rig_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `panel` sub-command."""
    p = subparsers.add_parser(
        "panel", help="the technician's panel: rig status, ARM/FIRE/ABORT, plots, DCM design, campaigns",
        description="Open the Qt panel for the rig (or for an in-process simulated rig with --sim).")
    add_rig_arguments(p)
    p.add_argument("--out", type=Path, default=Path("shots"), help="default folder for shot files (default %(default)s)")
    p.add_argument("--runs", type=Path, default=Path("runs"), help="folder for campaign runs (default %(default)s)")
    p.add_argument("--demo-shot", action="store_true",
                   help="with --sim: fire one shot (confirmation accepted), wait for its analysis, exit")
    p.add_argument("--screenshot", metavar="PATH",
                   help="save a PNG of the whole window (1280x800): after the demo shot, else after start-up")
    p.set_defaults(func=run_panel_command)


def run_panel_command(args: argparse.Namespace) -> int:
    from hopkinson.ui.app import run_panel  # Qt loads only for this command

    return run_panel(args)
