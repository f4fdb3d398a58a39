"""`hopkinson analyse`: analyse stored shots again with today's method.

    hopkinson analyse (SHOT.h5 | FOLDER)... [--jobs N] [--max-order N] [--order n] [--draws N]
                      [--no-uncertainty] [--sine SINE.csv] [--json]

Each shot is analysed from its raw channels with the options of its first analysis (or, never
analysed, its rig configuration's), changed only by the options given here; the result is
stored as a new analysis version beside the earlier ones, the file rewritten atomically
(rig/reanalysis.py, rig/shotfile_writer.py), never replacing raw data. A folder is searched through:
a campaign run folder gives its plan's shot files, and its journal follows (ANALYSED, or
ANALYSIS_FAILED with the reason), so `campaign run --resume` and the report see the new
analysis; every other `*.h5` file in the tree is analysed as it stands. This is how a lab
re-runs its archive after the method improves.

Shots are analysed --jobs at a time (default: the CPUs this process may use), each in a
worker process with single-threaded BLAS; a journal is written by this process once its
run's shots are done. Ctrl-C or SIGTERM: no new shot starts, the ones running finish and are
stored, the journals record them.

One line per shot, in the order found (its file, the new version, its key figures and verdict
("| ACCEPT: …" or "| REPEAT: …", its main reason) or why it
failed); --json one object {"shots": [{"path", "version", "ok", "error", "key_figures",
"summary", "verdict", "cpu_s"}]} (cpu_s: the CPU seconds the shot's analysis took). Exit codes
(docs/exit-codes.md): 0 every shot analysed and stored; 2 bad input (no such file, a folder with no shot file, a run folder
whose campaign is running, a journal that could not be updated); 4 a shot could not be
analysed or its analysis not stored (the others still are; each line says which and why).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.rig.cli.main import BLAS_THREAD_VARIABLES, emit_json
from hopkinson.rig.errors import EXIT_ANALYSIS_FAILED, ConfigError

if TYPE_CHECKING:  # concurrent.futures is loaded by this command only, not by every command's parser
    from concurrent.futures import Executor, Future

    from hopkinson.rig.reanalysis import Target

EXIT_SOME_FAILED = EXIT_ANALYSIS_FAILED  # as a shot whose analysis failed: 4, never 3 (aborted to safe)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `analyse` sub-command."""
    p = subparsers.add_parser("analyse", help="analyse stored shots (files, run folders, folder trees) again with "
                                              "today's method, in parallel",
                              description="Analyse stored shots again with today's method: a new analysis version "
                                          "in each shot file, the raw data untouched.")
    p.add_argument("sources", type=Path, nargs="+", metavar="SHOT.h5|FOLDER",
                   help="shot files, campaign run folders, or folders searched for both")
    p.add_argument("--jobs", "-j", type=_positive_int, default=None, metavar="N",
                   help=f"shots analysed at once (default: the CPUs this process may use, {available_cpus()})")
    p.add_argument("--max-order", type=int, metavar="N", help="highest model order tried")
    p.add_argument("--order", type=int, metavar="n", help="a fixed model order")
    p.add_argument("--draws", type=int, metavar="N", help="Monte Carlo draws of the uncertainty")
    p.add_argument("--no-uncertainty", dest="uncertainty", action="store_false", default=None,
                   help="no Monte Carlo uncertainty")
    p.add_argument("--sine", metavar="SINE.csv", help="a sine calibration of the sensor, fitted with each shock")
    p.add_argument("--json", action="store_true", help="one JSON object with every shot's outcome")
    p.set_defaults(func=analyse_command)


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def available_cpus() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def analyse_command(args: argparse.Namespace) -> int:
    from hopkinson.analysis.options import AnalysisOptions
    from hopkinson.rig.reanalysis import RunJournals, find_targets

    overrides = {k: v for k, v in (("max_order", args.max_order), ("order", args.order), ("draws", args.draws),
                                   ("uncertainty", args.uncertainty), ("sine_calibration", args.sine))
                 if v is not None}
    if overrides:
        AnalysisOptions.from_options(**overrides)  # checked before any shot is touched (AnalysisError: exit 2)
    targets = find_targets(args.sources)
    journals = RunJournals(targets)
    journals.check_free()
    jobs = min(args.jobs or available_cpus(), len(targets))
    rows: list[dict[str, Any]] = []
    futures: list[Future] = []

    def take(target: Target, future: Future) -> None:
        row = _row_of(target.path, future)
        rows.append(row)
        journals.done(target, row)
        if not args.json:
            print(_line(row), flush=True)

    # Ctrl-C is caught explicitly, as SIGTERM is: a process started with SIGINT ignored (by
    # a non-interactive shell or a test runner) would otherwise run the whole archive on.
    from hopkinson.rig.signals import exit_cleanly_on_termination

    try:
        with exit_cleanly_on_termination((signal.SIGINT, signal.SIGTERM, signal.SIGHUP)), _executor(jobs) as pool:
            futures = [pool.submit(_row, t.path, overrides) for t in targets]
            try:
                for target, future in zip(targets, futures, strict=True):
                    take(target, future)
            finally:
                for future in futures[len(rows):]:
                    future.cancel()  # not started: never will; running: finish and are stored
    finally:  # after an interruption the shots that finished are still told and reach their journals
        for target, future in zip(targets[len(rows):], futures[len(rows):], strict=False):
            if future.done() and not future.cancelled():
                take(target, future)
        problems = journals.close()
    if args.json:
        emit_json({"shots": [{k: v for k, v in row.items() if k != "journal"} for row in rows]})
    if problems:
        raise ConfigError("; ".join(problems))
    return 0 if all(row["ok"] for row in rows) else EXIT_SOME_FAILED


@contextlib.contextmanager
def _executor(jobs: int) -> Iterator[Executor]:
    """One worker thread for one job (in this process), else `jobs` worker processes, started
    from a fork server that has loaded the analysis once."""
    from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

    if jobs <= 1:
        with ThreadPoolExecutor(max_workers=1) as pool:
            yield pool
        return
    import multiprocessing

    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    context = multiprocessing.get_context(method)
    if method == "forkserver":
        context.set_forkserver_preload(["hopkinson.rig.reanalysis", "hopkinson.analysis.shot_analysis"])
    with _single_threaded_blas(), ProcessPoolExecutor(max_workers=jobs, mp_context=context,
                                                      initializer=_worker_start) as pool:
        yield pool


@contextlib.contextmanager
def _single_threaded_blas() -> Iterator[None]:
    """The BLAS thread variables set to 1 (where unset) while the workers start: N processes each
    with N BLAS threads would oversubscribe the cores (the `hopkinson` command sets them at its
    start; this covers a caller in Python)."""
    unset = [name for name in BLAS_THREAD_VARIABLES if name not in os.environ]
    os.environ.update({name: "1" for name in unset})
    try:
        yield
    finally:
        for name in unset:
            os.environ.pop(name, None)


def _worker_start() -> None:
    """Ctrl-C reaches the whole process group: the command stops starting shots, a worker
    finishes the one it has."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _row(path: Path, overrides: dict[str, Any]) -> dict[str, Any]:
    from hopkinson.rig.reanalysis import reanalysis_row

    return reanalysis_row(path, overrides)


def _row_of(path: Path, future: Future) -> dict[str, Any]:
    """The future's row, or a failed row when its worker died (killed, out of memory)."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 - a dead worker fails its shots, not the command
        return {"path": str(path), "version": None, "ok": False, "summary": None, "verdict": None, "key_figures": None,
                "cpu_s": None, "journal": None, "error": f"{path}: the analysis process failed: {type(exc).__name__}: {exc}"}


def _line(row: dict[str, Any]) -> str:
    where = f"{row['path']}: analysis version {row['version']}" if row["version"] else row["path"]
    if not row["ok"]:
        return f"{where}: FAILED: {row['error']}"
    verdict = row.get("verdict") or {}
    line = f"{where}: {row['summary'] or 'analysed'}"
    # still one line per shot: the decision and its main reason (the findings: --json, the report)
    return f"{line} | {verdict['decision']}: {verdict['reason']}" if verdict.get("decision") else line
