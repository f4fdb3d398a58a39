"""Coverage on hybrids of PTB's real shock record (issue 17): PTB's reference (its pulse, its
motion after the pulse, its noise) drives a known 55 kHz / ζ 0.03 sensor, with a real-shaped
disturbance injected — a lobe-dependent gain (tension/compression ×(1 − 0.7 s %) / ×(1 + 1.45 s %),
issue 17's measured asymmetry scaled by s), or the bar's motion after 0.7 ms reaching the sensor
at ×0.75 — and fresh response noise per seed. Counts how often the 95 % intervals of the FBSD
edges and the DC gain, and the response band inside the supported band, contain the truth.

Needs PyDynamic (the test extra). Not part of `make test` (it takes about a minute):

    .venv/bin/python benchmarks/coverage_ptb_hybrids.py [--seeds 4] [--draws 100]

Prints one line per case and, last, one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from scipy import signal  # noqa: E402

from hopkinson.analysis.errors import AnalysisError  # noqa: E402
from hopkinson.analysis.options import AnalysisOptions  # noqa: E402
from hopkinson.analysis.records import Record  # noqa: E402
from hopkinson.analysis.shot_analysis import analyse_record  # noqa: E402
from tests.analysis.test_ptb_identify import SENSITIVITY, hybrid_record, truth_fbsd_hz  # noqa: E402


def case_record(kind: str, scale: float, seed: int) -> tuple[Record, signal.lti]:
    if kind == "lobe":
        return hybrid_record(1.0 - 0.007 * scale, 1.0 + 0.0145 * scale, seed=seed)
    rec, truth = hybrid_record(seed=seed)
    if kind == "motion":
        after = rec.time_s - rec.time_s[0] >= 7.0e-4
        _, extra, _ = signal.lsim(truth, np.where(after, -0.25 * scale * rec.reference, 0.0),
                                  rec.time_s - rec.time_s[0])
        rec = Record(rec.sample_interval_s, rec.reference, rec.response + extra, response_unit="pC")
    return rec, truth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--draws", type=int, default=100)
    args = parser.parse_args()
    cases = [("clean", 0.0), ("lobe", 0.25), ("lobe", 0.5), ("lobe", 1.0), ("lobe", 2.0), ("motion", 1.0)]
    hits = {"fbsd_5": 0, "fbsd_10": 0, "dc_gain": 0, "response_band": 0}
    runs = failed = 0
    per_case = []
    for kind, scale in cases:
        row = {"case": f"{kind} x{scale:g}", "hits": {k: 0 for k in hits}, "runs": 0, "failed": 0}
        for seed in range(args.seeds):
            rec, truth = case_record(kind, scale, seed)
            try:
                a = analyse_record(rec, AnalysisOptions(draws=args.draws, seed=100 + seed))
            except AnalysisError:
                row["failed"] += 1
                continue
            unc = a.uncertainty or {}
            edges = truth_fbsd_hz(truth)
            ok = {}
            for level in ("5", "10"):
                lo, hi = unc["fbsd_hz"][level]["interval"]
                ok[f"fbsd_{level}"] = lo <= edges[level] <= hi
            lo, hi = unc["dc_gain"]["interval"]
            ok["dc_gain"] = lo <= SENSITIVITY <= hi
            band = unc["response_band"]
            f = np.array(band["frequency_hz"])
            _, h = signal.freqresp(truth, 2 * np.pi * f)
            rel = np.abs(h) / SENSITIVITY
            inside = f <= a.identification.supported_band_hz[1]
            ok["response_band"] = bool(np.all((np.array(band["magnitude_rel_low"])[inside] <= rel[inside])
                                              & (rel[inside] <= np.array(band["magnitude_rel_high"])[inside])))
            row["runs"] += 1
            for k, v in ok.items():
                row["hits"][k] += int(v)
        runs += row["runs"]
        failed += row["failed"]
        for k in hits:
            hits[k] += row["hits"][k]
        per_case.append(row)
        print(f"{row['case']:>12}: " + ", ".join(f"{k} {v}/{row['runs']}" for k, v in row["hits"].items())
              + (f", {row['failed']} refused" if row["failed"] else ""), flush=True)
    print(json.dumps({"benchmark": "coverage_ptb_hybrids", "seeds": args.seeds, "draws": args.draws, "runs": runs,
                      "failed": failed, "coverage": {k: v / runs if runs else None for k, v in hits.items()},
                      "cases": per_case}))


if __name__ == "__main__":
    main()
