"""Coverage on hybrids of PTB's real shock record (issue 17): PTB's reference (its pulse, its
motion after the pulse, its noise) drives a known 55 kHz / ζ 0.03 sensor, with a real-shaped
disturbance injected — a lobe-dependent gain (issue 17's measured asymmetry scaled by ×0.25 … ×2),
or the bar's motion after 0.7 ms reaching the sensor at ×0.75 — and fresh response noise per seed.
Counts how often each 95 % interval (FBSD edges, DC gain, f_n, ζ, the response band inside the
supported band, ε) contains the truth. The cases and the counting are
tests/studies/test_ptb_hybrids_coverage_powered.py's, which holds them with stated power in
`make studies`; this prints the table for other seed counts.

Needs PyDynamic (the test extra):

    .venv/bin/python benchmarks/coverage_ptb_hybrids.py [--seeds 13] [--draws 100]

Prints one line per case and, last, one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before NumPy loads: one process per core
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.studies import test_ptb_hybrids_coverage_powered as study  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=13)
    parser.add_argument("--draws", type=int, default=study.DRAWS)
    args = parser.parse_args()
    keys = [(case, seed) for case in study.CASES for seed in range(1, args.seeds + 1)]
    cases, seeds = zip(*keys, strict=True)
    with ProcessPoolExecutor(os.cpu_count() or 1) as pool:
        held = dict(zip(keys, pool.map(study.run, cases, seeds, [args.draws] * len(keys)), strict=True))
    totals: dict[str, list[int]] = {}
    per_case = []
    for case in study.CASES:
        counts: dict[str, list[int]] = {}
        for (c, _), figures in held.items():
            if c != case:
                continue
            for name, ok in figures.items():
                counts.setdefault(name, [0, 0])[0] += int(ok)
                counts[name][1] += 1
                totals.setdefault(name, [0, 0])[0] += int(ok)
                totals[name][1] += 1
        per_case.append({"case": case, "held": counts})
        print(f"{case:>11}: " + ", ".join(f"{k} {h}/{n}" for k, (h, n) in counts.items()), flush=True)
    print(json.dumps({"benchmark": "coverage_ptb_hybrids", "seeds": args.seeds, "draws": args.draws,
                      "coverage": {k: h / n for k, (h, n) in totals.items()},
                      "held": {k: f"{h}/{n}" for k, (h, n) in totals.items()}, "cases": per_case}))


if __name__ == "__main__":
    main()
