"""How far regenerated goldens moved from the committed ones (docs/golden-outputs.md): per golden,
the largest relative change of its point estimates and of its uncertainties (Monte Carlo
interval ends, standard uncertainties, budget shares), and every non-numeric change.

    .venv/bin/python tests/golden/golden_diff.py --rev HEAD~1        # the goldens at a commit vs tests/golden/outputs
    .venv/bin/python tests/golden/golden_diff.py OLD_DIR NEW_DIR     # two folders of goldens

A leaf counts as an uncertainty when a part of its JSON path is one of UNCERTAIN (the "value" of
an uncertainty block is its point estimate and counts as one); every other number is a point
estimate. Relative change: |new − old| / max(|old|, |new|).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

OUTPUTS = Path(__file__).resolve().parent / "outputs"
REPO = Path(__file__).resolve().parents[2]
UNCERTAIN = re.compile(
    r"(^|\.)(uncertainty|budget|interval|band_low|band_high|u|u_[a-z_]+|[a-z_]+_u|e_n|max_e_n|model_draws|"
    r"birge_ratio|chi2|p_value|draws|failed_draws|fractions|magnitude_rel_low|magnitude_rel_high|phase_low_deg|"
    r"phase_high_deg|coverage|consistent|points_beyond_e_n_1|verdict|stability)(\.|$)")

Change = tuple[float, str, Any, Any]


def leaves(obj: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    """(JSON path, value) of every leaf."""
    if isinstance(obj, dict):
        for key, value in obj.items():
            yield from leaves(value, f"{path}.{key}")
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            yield from leaves(value, f"{path}[{i}]")
    else:
        yield path, obj


def is_uncertainty(path: str) -> bool:
    """Whether the leaf at `path` is an uncertainty (module docstring)."""
    return not path.endswith(".value") and bool(UNCERTAIN.search(re.sub(r"\[\d+\]", "", path)))


def changes(old: Any, new: Any) -> tuple[list[Change], list[Change], list[tuple[str, Any, Any]]]:
    """The changed point estimates and uncertainties (largest relative change first), and the
    other changed leaves (text, flags, leaves present in one only)."""
    before, after = dict(leaves(old)), dict(leaves(new))
    points: list[Change] = []
    uncertainties: list[Change] = []
    other: list[tuple[str, Any, Any]] = []
    for path in sorted(before.keys() | after.keys()):
        x, y = before.get(path, "<missing>"), after.get(path, "<missing>")
        if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in (x, y)):
            if x != y:
                other.append((path, x, y))
            continue
        if x == y or (math.isnan(x) and math.isnan(y)):
            continue
        rel = abs(x - y) / max(abs(x), abs(y)) if math.isfinite(x) and math.isfinite(y) else math.inf
        (uncertainties if is_uncertainty(path) else points).append((rel, path, x, y))
    return sorted(points, reverse=True), sorted(uncertainties, reverse=True), other


def committed(rev: str, name: str) -> Any:
    text = subprocess.run(["git", "show", f"{rev}:tests/golden/outputs/{name}"], cwd=REPO, check=True,
                          capture_output=True, text=True).stdout
    return json.loads(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="*", help="OLD_DIR NEW_DIR (default: --rev against tests/golden/outputs)")
    parser.add_argument("--rev", help="the old goldens as committed at this git revision")
    parser.add_argument("--show", type=int, default=2, help="changes listed per golden and kind")
    args = parser.parse_args()
    new_dir = Path(args.folders[1]) if len(args.folders) == 2 else OUTPUTS
    worst_point = worst_uncertainty = 0.0
    for path in sorted(new_dir.glob("*.json")):
        if path.name.startswith("_"):
            continue
        old = committed(args.rev, path.name) if args.rev else json.loads((Path(args.folders[0]) / path.name).read_text())
        points, uncertainties, other = changes(old, json.loads(path.read_text()))
        p = points[0][0] if points else 0.0
        u = uncertainties[0][0] if uncertainties else 0.0
        worst_point, worst_uncertainty = max(worst_point, p), max(worst_uncertainty, u)
        print(f"{path.name:36s} point estimates: {len(points):4d} changed, largest {p:.2e};  "
              f"uncertainties: {len(uncertainties):4d} changed, largest {u:.2e};  other: {len(other)}")
        for kind, rows in (("point", points), ("uncertainty", uncertainties), ("other", other)):
            for row in rows[: args.show]:
                print(f"    {kind}: {row}")
    print(f"largest relative change: point estimates {worst_point:.2e}, uncertainties {worst_uncertainty:.2e}")


if __name__ == "__main__":
    main()
