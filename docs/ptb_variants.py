"""Which variants of PTB's shock record the intervals hold the sine calibration on (issue 17 item 3).

    .venv/bin/python docs/ptb_variants.py [--draws 400] [--only cut]

The record is read from the installed PyDynamic (the test extra), as the tests read it, and each
variant is made by tests/ptb_shock.py: one way a lab's other recording of the same shot would
differ (another sample rate, a capture cut shorter or started later, a skew between the
channels, more noise: 20 noises each at 1 and 2 % of the peak), alone and two or three at
once. For each it runs the whole shot analysis with its uncertainty and judges it as
tests/analysis/test_ptb_variants.py does (`against_sine`): both FBSD edges' 95 % intervals hold
the sine's (11.37 / 15.46 kHz) with half-widths of at most 25 %, the DC gain's holds the sine's
lowest point with at most 2 %, and the sine points lie in the model's 95 % response band with
their own uncertainty (E_n ≤ 1 at every point, analysis.sine_comparison.band_consistency). The
tests run a few of these; this study runs many more, so that
a change to the method can be judged on variants it was not tuned on. Rates of 1 MS/s
and above are analysed alike (the analysis resamples to 1 MS/s), so only 5 and 1 MS/s of them
are run. Last line: one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from hopkinson.analysis.options import AnalysisOptions  # noqa: E402
from hopkinson.analysis.records import Record  # noqa: E402
from hopkinson.analysis.shot_analysis import analyse_record  # noqa: E402
from hopkinson.analysis.sine_comparison import band_consistency, compare_sine  # noqa: E402
from tests.ptb_shock import (  # noqa: E402
    against_sine,
    cut,
    decimated,
    noisier,
    ptb_folder,
    ptb_sine,
    resampled,
    skewed,
    started_late,
)


def variants() -> dict[str, Callable[[], Record]]:
    out: dict[str, Callable[[], Record]] = {}
    for factor in (2, 10, 20, 40):
        out[f"{10 / factor:g} MS/s"] = lambda f=factor: decimated(f)
    out["4.29 MS/s (3/7)"] = lambda: resampled(3, 7)
    for n in (6_500, 7_000, 7_500, 8_000, 8_500, 9_000, 9_500, 10_000, 11_000, 12_000, 14_000, 16_000):
        out[f"{n / 1e4:g} ms capture"] = lambda n=n: cut(n)
    for s in (1_000, 2_000, 2_500, 2_800, 3_000, 3_300):
        out[f"started {s / 1e4:g} ms later"] = lambda s=s: started_late(s)
    for s in (-400, -200, -100, -50, -15, -5, 3, 8, 20, 30, 50, 100):
        out[f"skew {s / 10:+g} us"] = lambda s=s: skewed(s)
    # more noise: each seed another noise, as each recording would have its own
    noises = ([(1e-3, 0), (3e-3, 5), (5e-3, 9)] + [(level, seed) for level in (1e-2, 2e-2) for seed in range(20)]
              + [(3e-2, 0), (3e-2, 1), (3e-2, 2), (5e-2, 1)])
    for level, seed in noises:
        out[f"{100 * level:g} % more noise (seed {seed})"] = lambda lv=level, sd=seed: noisier(lv, sd)
    # two or three at once, as one lab's recording would differ in several ways
    out["2 MS/s, 0.8 ms"] = lambda: cut(1_600, decimated(5))
    out["0.85 ms, 0.5 % noise"] = lambda: cut(8_500, noisier(5e-3, 3))
    out["0.9 ms, skew -1 us"] = lambda: cut(9_000, skewed(-10))
    out["5 MS/s, skew, noise"] = lambda: decimated(2, noisier(3e-3, 4, skewed(5)))
    out["late 0.15 ms, 1 ms"] = lambda: cut(10_000, started_late(1_500))
    for seed in (1, 21):
        out[f"late 0.2 ms, 1 % noise ({seed})"] = lambda sd=seed: started_late(2_000, noisier(1e-2, sd))
    out["1 MS/s, late 0.25 ms, 2 % noise"] = lambda: decimated(10, started_late(2_500, noisier(2e-2, 32)))
    # a lead realigned (record_preparation.realigned) where the lead-in is short or the rate low
    out["late 0.2 ms, skew -10 us"] = lambda: started_late(2_000, skewed(-100))
    out["0.25 MS/s, skew -120 us"] = lambda: skewed(-30, decimated(40))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=400)
    parser.add_argument("--only", default="", help="run only the variants whose name contains this")
    args = parser.parse_args()
    try:
        ptb_folder()
    except (pytest.skip.Exception, pytest.fail.Exception) as exc:  # the tests' own check, as one line here
        print(f"docs/ptb_variants.py: {exc}", file=sys.stderr)
        sys.exit(2)
    sine = ptb_sine()
    results: dict[str, tuple[bool, bool]] = {}
    for name, make in variants().items():
        if args.only not in name:
            continue
        analysis = analyse_record(make(), AnalysisOptions(draws=args.draws, seed=1))
        judged = against_sine(analysis.uncertainty)
        e_n = band_consistency(compare_sine(analysis.model, sine), analysis.uncertainty["response_band"])
        intervals = all(j["contains"] and j["half_width_ok"] for j in judged.values())
        results[name] = (intervals, bool(e_n["consistent"]))
        worst = sine.frequency_hz[int(np.nanargmax(np.array(e_n["e_n"], dtype=float)))]
        print(f"{name:26s} " + "  ".join(_line(figure, j) for figure, j in judged.items())
              + f"  E_n ≤ {e_n['max_e_n']:.2f} ({worst / 1e3:.1f} kHz)" + ("" if e_n["consistent"] else " MISS"),
              flush=True)
    print(json.dumps({"study": "ptb_variants", "variants": len(results), "draws": args.draws,
                      "intervals_held": sum(i for i, _ in results.values()),
                      "e_n_held": sum(e for _, e in results.values()),
                      "all_held": sum(i and e for i, e in results.values()),
                      "missed": [name for name, (i, e) in results.items() if not (i and e)]}))


def _line(figure: str, j: dict) -> str:
    """One interval as printed: FBSD in kHz, the DC gain in % of the sine's; holds or why not."""
    verdict = ("holds" if j["contains"] and j["half_width_ok"]
               else "MISS (" + ", ".join(w for w, ok in (("truth outside", j["contains"]),
                                                         ("too wide", j["half_width_ok"])) if not ok) + ")")
    if figure == "dc_gain":
        rel = [100.0 * (v / j["truth"] - 1.0) for v in (j["value"], *j["interval"])]
        return f"DC {rel[0]:+.2f} % [{rel[1]:+.2f}, {rel[2]:+.2f}] {verdict}"
    lo, hi = j["interval"]
    return f"{figure.upper().replace('_', ' ±')} % {j['value'] / 1e3:.2f} [{lo / 1e3:.2f}, {hi / 1e3:.2f}] kHz {verdict}"


if __name__ == "__main__":
    main()
