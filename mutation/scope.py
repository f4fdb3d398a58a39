"""A cosmic-ray session filter: skip every mutation outside the functions a target names.

Used where a target is part of a module (the DCM's figures in analysis/dcm.py, the interval
logic in analysis/uncertainty.py). The functions are named in the target's configuration,

    [cosmic-ray.filters.scope]
    functions = ["compensated_fbsd_edges", "StepComparison.settling_times_samples", ...]

and their lines are found from the source each time, so the scope follows the code as it moves.
A name that is not found is an error (a renamed function must not silently leave the scope).

    python mutation/scope.py SESSION.sqlite CONFIG.toml
"""

from __future__ import annotations

import ast
import sys
from argparse import ArgumentParser, Namespace
from pathlib import Path

from cosmic_ray.config import load_config
from cosmic_ray.tools.filters.filter_app import FilterApp
from cosmic_ray.work_db import WorkDB
from cosmic_ray.work_item import WorkerOutcome, WorkResult


def function_lines(path: Path, names: list[str]) -> list[tuple[int, int]]:
    """(first, last) line of each named function or method ("Class.method"), decorators included."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found: dict[str, tuple[int, int]] = {}

    def visit(body: list[ast.stmt], prefix: str) -> None:
        for node in body:
            if isinstance(node, ast.ClassDef):
                visit(node.body, f"{prefix}{node.name}.")
            elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                found[f"{prefix}{node.name}"] = (first, node.end_lineno or node.lineno)

    visit(tree.body, "")
    missing = [name for name in names if name not in found]
    if missing:
        raise SystemExit(f"{path}: no function named {', '.join(missing)} (update the target's scope)")
    return [found[name] for name in names]


class ScopeFilter(FilterApp):
    """Skip the mutations outside the functions named in [cosmic-ray.filters.scope]."""

    def description(self) -> str:
        return __doc__ or ""

    def add_args(self, parser: ArgumentParser) -> None:
        parser.add_argument("config", help="the target's configuration (TOML)")

    def filter(self, work_db: WorkDB, args: Namespace) -> None:
        config = load_config(args.config)
        names = list(config.sub("filters", "scope").get("functions", ()))
        if not names:
            return
        paths = config["module-path"]
        (path,) = [paths] if isinstance(paths, str) else paths  # a scope names one module's functions
        ranges = function_lines(Path(path), names)
        outside = [item.job_id for item in work_db.pending_work_items
                   if not any(lo <= m.start_pos[0] <= hi for m in item.mutations for lo, hi in ranges)]
        if outside:
            work_db.set_multiple_results(
                outside, WorkResult(output="outside the target's scope", worker_outcome=WorkerOutcome.SKIPPED))


if __name__ == "__main__":
    sys.exit(ScopeFilter().main())
