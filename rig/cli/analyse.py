"""`hopkinson analyse`: analyse stored shots again with today's method.

    hopkinson analyse (SHOT.h5 | RUN_FOLDER)... [--max-order N] [--order n] [--draws N]
                      [--no-uncertainty] [--sine SINE.csv] [--json]

Each shot is analysed from its raw channels with the options of its last analysis (or, never
analysed, its rig configuration's), changed only by the options given here; the result is
stored as a new analysis version beside the earlier ones (rig/reanalysis.py, rig/shotfile.py),
never replacing raw data. A run folder: every shot file of its plan, and its journal follows
(ANALYSED, or ANALYSIS_FAILED with the reason), so `campaign run --resume` and the report see
the new analysis. This is also how a lab re-runs its archive after the method improves.

One line per shot (its file, the new version, its key figures or why it failed); --json one
object {"shots": [{"path", "version", "ok", "error", "key_figures", "summary"}]}.
Exit codes: 0 every shot analysed and stored; 2 bad input (no such file, not a shot file or run
folder, a run folder whose campaign is running); 3 a shot could not be analysed or its analysis
not stored (the others still are; each line says which and why).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from hopkinson.rig.cli.main import emit_json
from hopkinson.rig.errors import ConfigError

EXIT_SOME_FAILED = 3


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `analyse` sub-command."""
    p = subparsers.add_parser("analyse", help="analyse stored shots (files or run folders) again with today's method",
                              description="Analyse stored shots again with today's method: a new analysis version "
                                          "in each shot file, the raw data untouched.")
    p.add_argument("sources", type=Path, nargs="+", metavar="SHOT.h5|RUN_FOLDER")
    p.add_argument("--max-order", type=int, metavar="N", help="highest model order tried")
    p.add_argument("--order", type=int, metavar="n", help="a fixed model order")
    p.add_argument("--draws", type=int, metavar="N", help="Monte Carlo draws of the uncertainty")
    p.add_argument("--no-uncertainty", dest="uncertainty", action="store_false", default=None,
                   help="no Monte Carlo uncertainty")
    p.add_argument("--sine", metavar="SINE.csv", help="a sine calibration of the sensor, fitted with each shock")
    p.add_argument("--json", action="store_true", help="one JSON object with every shot's outcome")
    p.set_defaults(func=analyse_command)


def analyse_command(args: argparse.Namespace) -> int:
    from hopkinson.analysis.params import AnalysisParams

    overrides = {k: v for k, v in (("max_order", args.max_order), ("order", args.order), ("draws", args.draws),
                                   ("uncertainty", args.uncertainty), ("sine_calibration", args.sine))
                 if v is not None}
    if overrides:
        AnalysisParams.from_options(**overrides)  # checked before any shot is touched (AnalysisError: exit 2)
    targets = [target for source in args.sources for target in _targets(source)]
    rows = [_analyse_one(path, journal_of, shot_id, overrides) for path, journal_of, shot_id in targets]
    if args.json:
        emit_json({"shots": rows})
    else:
        for row in rows:
            print(_line(row))
    return 0 if all(row["ok"] for row in rows) else EXIT_SOME_FAILED


def _targets(source: Path) -> list[tuple[Path, Path | None, str | None]]:
    """(shot file, its run folder or None, its shot id or None) for a shot file or a run folder."""
    from hopkinson.rig.run_folder import PLAN_NAME, open_run_folder

    if source.is_dir():
        if not (source / PLAN_NAME).is_file():
            raise ConfigError(f"{source}: not a campaign run folder (no {PLAN_NAME}) and not a shot file")
        run = open_run_folder(source)
        found = [(run.shot_path(s.id), source, s.id) for s in run.load_plan().shots if run.shot_path(s.id).exists()]
        if not found:
            raise ConfigError(f"{source}: no shot files yet; nothing to analyse")
        return found
    if not source.is_file():
        raise ConfigError(f"{source}: no such shot file or run folder")
    return [(source, None, None)]


def _analyse_one(path: Path, run_folder: Path | None, shot_id: str | None, overrides: dict[str, Any]) -> dict[str, Any]:
    from hopkinson.analysis.key_figures import KeyFigures
    from hopkinson.rig.campaign import result_line
    from hopkinson.rig.reanalysis import reanalyse
    from hopkinson.rig.shotfile import ShotFileError, read_shot

    row: dict[str, Any] = {"path": str(path), "version": None, "ok": False, "error": None, "key_figures": None,
                           "summary": None}
    try:
        recorded = reanalyse(path, overrides)
    except (ShotFileError, ConfigError, ValueError) as exc:
        row["error"] = str(exc)
        return row
    if recorded.stored:
        row["version"] = read_shot(path, load_raw=False).analyses[-1]["version"]
    row["ok"] = recorded.error is None
    row["error"] = recorded.error
    if recorded.results is not None:
        row["key_figures"] = KeyFigures.from_results(recorded.results).to_dict()
        row["summary"] = result_line(recorded.results)
    if run_folder is not None and shot_id is not None and recorded.stored:
        _update_journal(run_folder, shot_id, recorded.results, recorded.error)
    return row


def _update_journal(run_folder: Path, shot_id: str, results: dict[str, Any] | None, error: str | None) -> None:
    """The run's journal follows the shot file (ConfigError when the campaign is running)."""
    from hopkinson.rig.campaign import result_info
    from hopkinson.rig.journal import Journal, JournalError, ShotState

    try:
        with Journal.open(run_folder) as journal:
            if journal.status(shot_id).state in (ShotState.RECORDED, ShotState.ANALYSED, ShotState.ANALYSIS_FAILED):
                if error is None:
                    journal.mark(shot_id, ShotState.ANALYSED, redo=False, **result_info(results))
                else:
                    journal.mark(shot_id, ShotState.ANALYSIS_FAILED, error=error, redo=False)
    except JournalError as exc:
        raise ConfigError(f"{run_folder}: the journal was not updated ({exc})") from None


def _line(row: dict[str, Any]) -> str:
    where = f"{row['path']}: analysis version {row['version']}" if row["version"] else row["path"]
    if not row["ok"]:
        return f"{where}: FAILED: {row['error']}"
    return f"{where}: {row['summary'] or 'analysed'}"
