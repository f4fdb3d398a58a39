"""Which variants of PTB's shock record the intervals hold the sine calibration on (issue 17 item 3).

    .venv/bin/python docs/ptb_variants.py [--draws 60] [--only cut]

The record is read from the installed PyDynamic (the test extra), as the tests read it. Each
variant is one way a lab's other recording of the same shot would differ: another sample rate,
a capture cut shorter or started later, a skew between the channels, more noise. For each it
runs the whole shot analysis with its uncertainty and checks what
tests/analysis/test_ptb_variants.py checks: both FBSD edges' 95 % intervals hold the sine's
(11.37 / 15.46 kHz) with half-widths of at most 25 %, the DC gain's holds the sine's lowest point
with at most 2 %. The tests run a few of these; this study runs many more, so that a change to
the method can be judged on variants it was not tuned on. Last line: one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy import signal

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from hopkinson.analysis.params import AnalysisParams  # noqa: E402
from hopkinson.analysis.records import Record  # noqa: E402
from hopkinson.analysis.shot_analysis import analyse_record  # noqa: E402

from tests.analysis.test_ptb_variants import cut, decimated, noisier, skewed  # noqa: E402
from tests.ptb_shock import SINE_FBSD_5_HZ, SINE_FBSD_10_HZ, ptb_record, ptb_sine  # noqa: E402


def resampled(up: int, down: int) -> Record:
    """The record at 10 MS/s × up / down (polyphase)."""
    rec = ptb_record()
    ref, resp = (signal.resample_poly(x, up, down) for x in (rec.reference, rec.response))
    return Record(rec.sample_interval_s * down / up, ref, resp, response_unit="pC")


def started_late(samples: int) -> Record:
    """The capture started `samples` later (a shorter lead-in before the pulse)."""
    rec = ptb_record()
    return Record(rec.sample_interval_s, rec.reference[samples:], rec.response[samples:], response_unit="pC")


def variants() -> dict[str, Callable[[], Record]]:
    out: dict[str, Callable[[], Record]] = {}
    for factor in (2, 4, 5, 10, 20):
        out[f"{10 / factor:g} MS/s"] = lambda f=factor: decimated(f)
    out["4.29 MS/s (3/7)"] = lambda: resampled(3, 7)
    for n in (7_000, 7_500, 8_000, 8_500, 9_000, 9_500, 10_000, 11_000, 12_000, 14_000, 16_000):
        out[f"{n / 1e4:g} ms capture"] = lambda n=n: cut(n)
    for s in (1_000, 2_500):
        out[f"started {s / 1e4:g} ms later"] = lambda s=s: started_late(s)
    for s in (-15, -5, 3, 8, 20):
        out[f"skew {s / 10:+g} us"] = lambda s=s: skewed(s)
    for level, seed in ((1e-3, 0), (3e-3, 5), (5e-3, 9), (1e-2, 1), (1e-2, 7)):
        out[f"{100 * level:g} % more noise (seed {seed})"] = lambda lv=level, sd=seed: noisier(lv, sd)
    return out


def judged(record: Record, draws: int) -> dict[str, object]:
    """The intervals and whether each holds the sine's value within the issue's half-width."""
    unc = analyse_record(record, AnalysisParams(draws=draws, seed=1)).uncertainty
    out: dict[str, object] = {}
    for level, sine_hz in (("5", SINE_FBSD_5_HZ), ("10", SINE_FBSD_10_HZ)):
        edge = unc["fbsd_hz"][level]
        lo, hi = edge["interval"]
        out[f"fbsd_{level}"] = {"value": edge["value"], "interval": [lo, hi],
                                "holds": bool(lo <= sine_hz <= hi and (hi - lo) / 2 <= 0.25 * edge["value"])}
    sine_dc = float(ptb_sine().magnitude[0])
    lo, hi = unc["dc_gain"]["interval"]
    out["dc_gain_rel"] = {"value": unc["dc_gain"]["value"] / sine_dc - 1.0, "interval": [lo / sine_dc - 1.0,
                                                                                        hi / sine_dc - 1.0],
                          "holds": bool(lo <= sine_dc <= hi and (hi - lo) / 2 <= 0.02 * unc["dc_gain"]["value"])}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=60)
    parser.add_argument("--only", default="", help="run only the variants whose name contains this")
    args = parser.parse_args()
    results = {}
    for name, make in variants().items():
        if args.only not in name:
            continue
        r = judged(make(), args.draws)
        results[name] = r
        f5, f10, dc = r["fbsd_5"], r["fbsd_10"], r["dc_gain_rel"]
        print(f"{name:28s} FBSD5 {f5['value'] / 1e3:6.2f} [{f5['interval'][0] / 1e3:6.2f}, "
              f"{f5['interval'][1] / 1e3:6.2f}] kHz {'holds' if f5['holds'] else 'MISS '}  "
              f"FBSD10 {f10['value'] / 1e3:6.2f} [{f10['interval'][0] / 1e3:6.2f}, "
              f"{f10['interval'][1] / 1e3:6.2f}] kHz {'holds' if f10['holds'] else 'MISS '}  "
              f"DC {100 * dc['value']:+.2f} % [{100 * dc['interval'][0]:+.2f}, {100 * dc['interval'][1]:+.2f}] "
              f"{'holds' if dc['holds'] else 'MISS'}", flush=True)
    held = sum(all(v["holds"] for v in r.values()) for r in results.values())
    print(json.dumps({"study": "ptb_variants", "variants": len(results), "all_held": held,
                      "missed": [n for n, r in results.items() if not all(v["holds"] for v in r.values())]}))


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
