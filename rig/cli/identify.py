"""`hopkinson identify`: the accelerometer's dynamic model from a two-channel record.

    hopkinson identify RECORD [--max-order N] [--order n] [--sample-rate HZ] [--json] [-o model.json]

RECORD is a CSV (time_s,reference,response) or NPZ with the same keys. The JSON (printed
with --json, written by -o) is the model file `hopkinson dcm --model` reads: sample interval,
order, a, b, poles and zeros as [re, im] pairs, DC gain, loss by order, FBSD (Hz) and the
paper's Table-1 pole analysis, plus the fit details.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.analysis.errors import AnalysisError
from hopkinson.rig.cli.main import emit_json

if TYPE_CHECKING:
    from hopkinson.analysis.identify import Identification


def identification_report(result: Identification, source: str) -> dict[str, Any]:
    """The JSON object of `hopkinson identify` (also what -o writes)."""
    from hopkinson.analysis.response import fbsd_hz, pole_analysis

    report = {"source": source, **result.to_dict()}
    report["fbsd_hz"] = fbsd_hz(result.model)
    report["pole_analysis"] = pole_analysis(result.poles)
    return report


def _summary(report: dict[str, Any], result: Identification) -> str:
    """A short human-readable account of the identification."""
    lines = [
        f"{report['source']}: order {result.order} ({'chosen at the knee of the loss' if result.order_selection == 'knee' else 'as asked'}), "
        f"fit {result.fit_percent:.2f} %, sample interval {result.sample_interval_s:g} s, "
        f"delay {result.delay_samples:g} samples",
    ]
    for mode in result.modes:
        pole = complex(*mode["pole"])
        sign = "±" if mode["kind"] == "complex" else ""
        f_n, zeta = mode["natural_frequency_hz"], mode["damping_ratio"]
        where = f"f_n = {f_n / 1e3:.4g} kHz, ζ = {zeta:.4g}" if f_n is not None and zeta is not None else "at the origin"
        lines.append(f"  pole {pole.real:.6f} {sign}{abs(pole.imag):.6f}j  ({mode['kind']}): {where}")
    fbsd = report["fbsd_hz"]
    lines.append(f"  FBSD: ±5 % up to {fbsd['5'] / 1e3:.4g} kHz, ±10 % up to {fbsd['10'] / 1e3:.4g} kHz")
    lines.append(f"  DC gain {result.model.dc_gain:.6g} (response units per m/s²)")
    losses = ", ".join(
        f"{n}: {v:.4g}" for n, v in enumerate(result.loss_by_order, start=1) if math.isfinite(v)
    )
    lines.append(f"  bias-corrected loss by order: {losses}")
    for warning in result.warnings:
        lines.append(f"  warning: {warning}")
    return "\n".join(lines)


def run_identify(args: argparse.Namespace) -> int:
    """Identify the model of RECORD; print a summary or the JSON; optionally write the JSON."""
    from hopkinson.analysis.identify import identify
    from hopkinson.analysis.records import read_record
    from hopkinson.analysis.resample import DEFAULT_ANALYSIS_RATE_HZ

    if args.max_order < 1:
        raise AnalysisError(f"--max-order must be at least 1, got {args.max_order}")
    if args.order is not None and args.order < 1:
        raise AnalysisError(f"--order must be at least 1, got {args.order}")
    if args.sample_rate is not None and not (math.isfinite(args.sample_rate) and args.sample_rate > 0):
        raise AnalysisError(f"--sample-rate must be a positive number of Hz, got {args.sample_rate}")
    record = read_record(args.record)
    sample_rate_hz = DEFAULT_ANALYSIS_RATE_HZ if args.sample_rate is None else args.sample_rate
    try:
        result = identify(record, max_order=args.max_order, order=args.order, sample_rate_hz=sample_rate_hz)
    except AnalysisError as exc:
        raise AnalysisError(f"{args.record}: {exc}") from None
    report = identification_report(result, str(args.record))
    if args.output:
        out = Path(args.output)
        try:
            out.write_text(json.dumps(report, indent=2, allow_nan=False) + "\n")
        except OSError as exc:
            raise AnalysisError(f"{out}: cannot write the model file ({exc.strerror})") from None
    if args.json:
        emit_json(report)
    else:
        sys.stdout.write(_summary(report, result) + "\n")
        if args.output:
            sys.stdout.write(f"model written to {args.output}\n")
    return 0


def register(subparsers: Any) -> None:
    """Add the `identify` sub-command."""
    p = subparsers.add_parser(
        "identify",
        help="identify the accelerometer's discrete model from a two-channel record",
        description="Identify A(d^-1) y = B(d^-1) u from RECORD (CSV time_s,reference,response or NPZ): "
        "resample to the analysis rate, remove the channel delay, compute the loss of every order from one "
        "factorisation, correct the bias (refined instrumental variables, prefilter 1/A) and choose the "
        "order where the bias-corrected loss stops falling.",
    )
    p.add_argument("record", metavar="RECORD", help="two-channel record (CSV or NPZ)")
    p.add_argument("--max-order", type=int, default=12, metavar="N", help="largest order tried (default 12)")
    p.add_argument("--order", type=int, metavar="n", help="fit exactly this order instead of choosing it")
    p.add_argument(
        "--sample-rate",
        type=float,
        metavar="HZ",
        # None: analysis.resample.DEFAULT_ANALYSIS_RATE_HZ, resolved in run_identify (scipy loads there)
        help="analysis rate: a record sampled faster is low-pass filtered and resampled (default 1e6)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--output", metavar="MODEL.json", help="write the model JSON (read by `hopkinson dcm --model`)")
    p.set_defaults(func=run_identify)
