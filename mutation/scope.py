"""A cosmic-ray session filter: skip every mutation outside the functions a target names, and
every mutation inside an annotation of a module that has `from __future__ import annotations`
(annotations are then strings never evaluated: `float | None` → `float - None` is equivalent by
construction).

Used where a target is part of a module (the DCM's noise gain in analysis/dcm.py, the interval
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


def function_lines(path: Path, names: list[str]) -> dict[str, tuple[int, int]]:
    """{name: (first, last) line} of the named functions or methods ("Class.method") that `path`
    defines, decorators included."""
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
    return {name: found[name] for name in names if name in found}


def annotation_spans(path: Path) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """(start, end) (line, column) of every annotation when they are not evaluated, else none."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    postponed = any(isinstance(node, ast.ImportFrom) and node.module == "__future__"
                    and any(alias.name == "annotations" for alias in node.names) for node in tree.body)
    if not postponed:
        return []
    nodes: list[ast.expr] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.arg) and node.annotation is not None:
            nodes.append(node.annotation)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.returns is not None:
            nodes.append(node.returns)
        elif isinstance(node, ast.AnnAssign):
            nodes.append(node.annotation)
    return [((n.lineno, n.col_offset), (n.end_lineno or n.lineno, n.end_col_offset or 0)) for n in nodes]


class ScopeFilter(FilterApp):
    """Skip the mutations outside the functions named in [cosmic-ray.filters.scope]."""

    def description(self) -> str:
        return __doc__ or ""

    def add_args(self, parser: ArgumentParser) -> None:
        parser.add_argument("config", help="the target's configuration (TOML)")

    def filter(self, work_db: WorkDB, args: Namespace) -> None:
        config = load_config(args.config)
        paths = config["module-path"]
        paths = [paths] if isinstance(paths, str) else list(paths)
        spans = {Path(p): annotation_spans(Path(p)) for p in paths}
        annotations = [item.job_id for item in work_db.pending_work_items
                       if all(any(a <= tuple(m.start_pos) < b for a, b in spans.get(Path(m.module_path), []))
                              for m in item.mutations)]
        if annotations:
            work_db.set_multiple_results(annotations, WorkResult(
                output="in an annotation, never evaluated (from __future__ import annotations)",
                worker_outcome=WorkerOutcome.SKIPPED))
        names = list(config.sub("filters", "scope").get("functions", ()))
        if not names:
            return
        # the scope's functions, each in whichever of the target's modules defines it
        ranges = {Path(p): function_lines(Path(p), names) for p in paths}
        missing = [n for n in names if not any(n in found for found in ranges.values())]
        if missing:
            raise SystemExit(f"{', '.join(paths)}: no function named {', '.join(missing)} (update the target's scope)")
        outside = [item.job_id for item in work_db.pending_work_items
                   if not any(lo <= m.start_pos[0] <= hi for m in item.mutations
                              for lo, hi in ranges.get(Path(m.module_path), {}).values())]
        if outside:
            work_db.set_multiple_results(
                outside, WorkResult(output="outside the target's scope", worker_outcome=WorkerOutcome.SKIPPED))


if __name__ == "__main__":
    sys.exit(ScopeFilter().main())
