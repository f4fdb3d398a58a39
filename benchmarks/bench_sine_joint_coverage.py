"""Coverage study of the joint fit of a shock record and a sine calibration (analysis.sine_joint):
on a simulated sensor with a known truth (tests/analysis/hard_records.py's default case: 27 kHz,
ζ 0.05, a 20 µs half-sine, 1 % noise on both channels) and a sine calibration drawn from the
truth with its stated noise (40 points 0.5–20 kHz, 0.3 % / 0.3°), over many seeds:

- how often the 95 % intervals of the joint model's figures (FBSD ±5 % / ±10 %, f_n, ζ, DC gain)
  contain the truth, beside the shock-only model's;
- how often the consistency verdict calls a sine of the same sensor inconsistent (its false
  alarm rate; 5 % by construction of the χ² test at 95 %), and a sine of a 40 kHz sensor
  consistent (its miss rate).

    .venv/bin/python benchmarks/bench_sine_joint_coverage.py [--seeds 40] [--draws 100]

Prints the figures and, on its last line, one JSON object. (The test suite checks one seed's
intervals and the false-alarm rate over 8 seeds: tests/analysis/test_sine_joint.py.)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopkinson.analysis.identify import identify, identify_with_sine  # noqa: E402
from hopkinson.analysis.options import AnalysisOptions  # noqa: E402
from hopkinson.analysis.uncertainty import evaluate  # noqa: E402
from tests.analysis.hard_records import Case, record, truth_figures  # noqa: E402
from tests.analysis.test_sine_joint import OTHER, synthetic_sine  # noqa: E402

FIGURES = ("fbsd_5", "fbsd_10", "natural_frequency_hz", "damping_ratio", "dc_gain")


def contains(result: Any, truth: dict[str, float]) -> dict[str, bool]:
    estimates = {"fbsd_5": result.fbsd_hz["5"], "fbsd_10": result.fbsd_hz["10"],
                 "natural_frequency_hz": result.natural_frequency_hz, "damping_ratio": result.damping_ratio,
                 "dc_gain": result.dc_gain}
    return {k: e is not None and e.interval[0] <= truth[k] <= e.interval[1] for k, e in estimates.items()}


def run(seeds: int, draws: int) -> dict[str, Any]:
    case = Case()
    truth = truth_figures(case)
    hits = {"shock": dict.fromkeys(FIGURES, 0), "joint": dict.fromkeys(FIGURES, 0)}
    false_alarms = misses = 0
    start = time.perf_counter()
    for seed in range(seeds):
        rec = record(case, 1000 + seed)
        options = AnalysisOptions(draws=draws, seed=seed)
        for name, sine in (("shock", None), ("joint", synthetic_sine(case.truth, 1000 + seed))):
            ident = identify(rec) if sine is None else identify_with_sine(rec, sine)
            for k, ok in contains(evaluate(ident, options), truth).items():
                hits[name][k] += ok
            if sine is not None:
                false_alarms += not ident.sine_joint.consistent
        misses += identify_with_sine(rec, synthetic_sine(OTHER, 1000 + seed)).sine_joint.consistent
    out = {
        "benchmark": "sine_joint_coverage",
        "seeds": seeds,
        "draws": draws,
        "coverage_shock_only": {k: v / seeds for k, v in hits["shock"].items()},
        "coverage_joint": {k: v / seeds for k, v in hits["joint"].items()},
        "verdict_false_alarm_rate": false_alarms / seeds,
        "verdict_miss_rate_other_sensor": misses / seeds,
        "seconds": time.perf_counter() - start,
    }
    for name in ("shock_only", "joint"):
        parts = ", ".join(f"{k} {100 * v:.0f} %" for k, v in out[f"coverage_{name}"].items())
        print(f"{name}: 95 % intervals containing the truth over {seeds} seeds: {parts}")
    print(f"verdict: same sensor called inconsistent {100 * out['verdict_false_alarm_rate']:.0f} %, "
          f"a 40 kHz sensor called consistent {100 * out['verdict_miss_rate_other_sensor']:.0f} %")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--draws", type=int, default=100)
    args = parser.parse_args()
    print(json.dumps(run(args.seeds, args.draws), allow_nan=False))


if __name__ == "__main__":
    main()
