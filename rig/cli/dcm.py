"""`hopkinson dcm` (design a dynamic compensation model) and `hopkinson compensate` (apply one).

    hopkinson dcm (--model model.json | --poles P,P,… --sample-interval S) --ratio R --damping Z
                  [--extra-poles P,…] [--json] [-o dcm.json]
    hopkinson compensate RECORD --dcm dcm.json -o out.csv [--block-samples N] [--initial steady|rest] [--json]

Poles are written like 0.974+0.1396j (or …i), every pole listed, both members of a
conjugate pair. A list that starts with a minus sign needs the = form: --poles=-0.5,0.3.
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
    import numpy as np
    from hopkinson.analysis.dcm import DCM
    from hopkinson.analysis.model import DiscreteModel

DEFAULT_BLOCK_SAMPLES = 65_536


def parse_complex(text: str, option: str) -> complex:
    """One pole such as 0.974+0.1396j, 0.974-0.1396i or 0.5; clear error otherwise."""
    raw = text.strip().replace(" ", "")
    if not raw:
        raise AnalysisError(f"{option}: empty pole in the list (write poles like 0.974+0.1396j, comma-separated)")
    try:
        value = complex(raw.replace("i", "j").replace("I", "j").replace("J", "j"))
    except ValueError:
        raise AnalysisError(f"{option}: {text.strip()!r} is not a complex number (write poles like 0.974+0.1396j)") from None
    if not (math.isfinite(value.real) and math.isfinite(value.imag)):
        raise AnalysisError(f"{option}: {text.strip()!r} is not a finite number")
    return value


def parse_poles(text: str, option: str) -> np.ndarray:
    """A comma-separated list of poles."""
    import numpy as np

    return np.array([parse_complex(part, option) for part in text.split(",")], dtype=complex)


def _load_model_checked(path: str) -> DiscreteModel:
    """load_model, with any malformed content turned into one clear message."""
    from hopkinson.analysis.model import load_model

    try:
        model = load_model(path)
    except AnalysisError:
        raise
    except (TypeError, ValueError, IndexError) as exc:
        raise AnalysisError(f"{path}: not a valid model file ({exc})") from None
    if model.a.ndim != 1 or model.b.ndim != 1:
        raise AnalysisError(f"{path}: 'a' and 'b' must be flat lists of numbers")
    if model.order < 1:
        raise AnalysisError(f"{path}: the model has no poles (a = {list(model.a)}); nothing to compensate")
    return model


def design_report(
    poles: np.ndarray, dcm: DCM, model: DiscreteModel | None, source: str
) -> dict[str, Any]:
    """The JSON result of `hopkinson dcm` (also what -o writes)."""
    from hopkinson.analysis.dcm import compare_steps, compensated_fbsd_edges
    from hopkinson.analysis.response import fbsd_edges, pole_analysis

    result: dict[str, Any] = {
        "source": source,
        "sample_interval_s": dcm.sample_interval_s,
        "pole_analysis": pole_analysis(poles),
        "dcm": dcm.to_dict(),
    }
    if model is not None:
        before = fbsd_edges(model)
        after = compensated_fbsd_edges(model, dcm)
        steps = compare_steps(model, dcm)  # one step-response simulation for both times
        rt_before, rt_after = steps.rise_times_samples()
        result["fbsd_hz"] = {k: e.frequency_hz for k, e in before.items()}
        result["compensated_fbsd_hz"] = {k: e.frequency_hz for k, e in after.items()}
        result["fbsd_detail"] = {k: e.to_dict() for k, e in before.items()}
        result["compensated_fbsd_detail"] = {k: e.to_dict() for k, e in after.items()}
        result["fbsd_widening"] = {k: after[k].frequency_hz / before[k].frequency_hz for k in before}
        result["rise_time_samples"] = {"uncompensated": rt_before, "compensated": rt_after}
        result["rise_time_ratio"] = rt_before / rt_after if rt_after > 0 else None
        st_before, st_after = steps.settling_times_samples()
        result["settling_time_samples"] = {"uncompensated": st_before, "compensated": st_after}
        result["settling_time_ratio"] = steps.settling_time_ratio()
    return result


def _poly_text(coeffs: np.ndarray) -> str:
    n = len(coeffs) - 1
    terms = []
    for i, c in enumerate(coeffs):
        power = n - i
        z = "" if power == 0 else ("z" if power == 1 else f"z^{power}")
        terms.append(f"{c:+.6g}{'·' if z else ''}{z}")
    return " ".join(terms).lstrip("+")


def _print_design(result: dict[str, Any], dcm: DCM) -> None:
    from hopkinson.analysis.dcm import format_complex

    out = sys.stdout
    out.write(f"Model: {result['source']} (sample interval {dcm.sample_interval_s:g} s)\n")
    out.write("Pole analysis (paper Table 1; response time in samples):\n")
    out.write(f"  {'pole':<26}{'T_r':>12}{'r_i':>10}\n")
    for row in result["pole_analysis"]:
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.2f}"
        out.write(f"  {format_complex(complex(*row['pole'])):<26}{row['response_time_samples']:>12.2f}{ratio:>10}\n")
    d = dcm.design
    out.write(
        f"DCM: r = {d['ratio']:g}, zeta_e = {d['damping']:g}: target response time {d['target_response_time_samples']:.3f} "
        f"samples; designed poles {', '.join(format_complex(complex(*p)) for p in d['designed_poles'])}\n"
    )
    if d["extra_poles"]:
        out.write(f"  extra poles: {', '.join(format_complex(complex(*p)) for p in d['extra_poles'])}\n")
    if d["origin_poles"]:
        out.write(
            f"  {d['origin_poles']} pole(s) placed at z = 0 to make the DCM causal: "
            f"its output lags by {d['origin_poles']} sample(s); the magnitude is as designed\n"
        )
    out.write(f"  num: {_poly_text(dcm.num)}\n  den: {_poly_text(dcm.den)}\n  gain K = {dcm.gain:.6g} (G(1) = 1)\n")
    if "fbsd_hz" in result:
        for key in result["fbsd_hz"]:
            before, after = result["fbsd_detail"][key], result["compensated_fbsd_detail"][key]
            note = " (never left the band below Nyquist)" if after["within_band_to_limit"] else ""
            out.write(
                f"FBSD ±{key} %: {before['frequency_hz'] / 1e3:.3f} kHz -> {after['frequency_hz'] / 1e3:.3f} kHz "
                f"(x{result['fbsd_widening'][key]:.2f}){note}\n"
            )
        rt, ratio = result["rise_time_samples"], result["rise_time_ratio"]
        factor = "" if ratio is None else f" (ratio {ratio:.2f}: {'faster' if ratio > 1 else 'NOT faster'})"
        out.write(f"Rise time 10-90 %: {rt['uncompensated']:.3f} -> {rt['compensated']:.3f} samples{factor}\n")
        st, sratio = result["settling_time_samples"], result["settling_time_ratio"]
        verdict = "shorter" if sratio > 1 else "NOT shorter"
        out.write(f"Settling time to ±5 %: {st['uncompensated']:.0f} -> {st['compensated']:.0f} samples "
                  f"(ratio {sratio:.2f}: {verdict})\n")


def run_dcm(args: argparse.Namespace) -> int:
    """Design the DCM and report it (text or --json); -o writes the DCM file."""
    from hopkinson.analysis.dcm import design_dcm

    if (args.model is None) == (args.poles is None):
        raise AnalysisError("dcm: give either --model FILE or --poles P,P,… (with --sample-interval)")
    model: DiscreteModel | None = None
    if args.model is not None:
        if args.sample_interval is not None:
            raise AnalysisError("dcm: --sample-interval goes with --poles; a model file carries its own")
        model = _load_model_checked(args.model)
        poles, dt, source = model.poles, model.sample_interval_s, str(args.model)
    else:
        if args.sample_interval is None:
            raise AnalysisError("dcm: --poles needs --sample-interval S (seconds, e.g. 1e-6)")
        if not args.sample_interval > 0:
            raise AnalysisError(f"dcm: --sample-interval must be positive, got {args.sample_interval}")
        poles, dt, source = parse_poles(args.poles, "--poles"), args.sample_interval, "--poles"
    extra = parse_poles(args.extra_poles, "--extra-poles") if args.extra_poles else ()
    dcm = design_dcm(poles, dt, args.ratio, args.damping, extra)
    result = design_report(poles, dcm, model, source)
    if args.output:
        path = Path(args.output)
        try:
            path.write_text(json.dumps(result, indent=2, allow_nan=False) + "\n")
        except OSError as exc:
            raise AnalysisError(f"{path}: cannot write the DCM file ({exc.strerror})") from None
        result["output"] = str(path)
    if args.json:
        emit_json(result)
    else:
        _print_design(result, dcm)
        if args.output:
            sys.stdout.write(f"wrote {args.output}\n")
    return 0


def run_compensate(args: argparse.Namespace) -> int:
    """Apply a DCM to a record's response, block by block, and write the compensated record."""
    from hopkinson.analysis.dcm import apply, load_dcm
    from hopkinson.analysis.records import read_record, write_record

    if args.block_samples < 1:
        raise AnalysisError(f"compensate: --block-samples must be at least 1, got {args.block_samples}")
    dcm = load_dcm(args.dcm)
    record = read_record(args.record)
    if abs(record.sample_interval_s - dcm.sample_interval_s) > 1e-3 * dcm.sample_interval_s:
        raise AnalysisError(
            f"{args.record}: sampled every {record.sample_interval_s:g} s but the DCM in {args.dcm} was designed "
            f"for {dcm.sample_interval_s:g} s; resample the record first"
        )
    compensated = apply(dcm, record.response, args.initial, args.block_samples)
    n_blocks = -(-record.n_samples // args.block_samples)
    out = type(record)(record.sample_interval_s, record.reference, compensated, record.start_time_s)
    try:
        write_record(args.output, out)
    except OSError as exc:
        raise AnalysisError(f"{args.output}: cannot write the record ({exc.strerror})") from None
    what = (
        f"compensated the response column of {args.record} ({record.n_samples} samples) with the order-{dcm.order} "
        f"DCM of {args.dcm}, streamed in {n_blocks} block(s) of up to {args.block_samples} samples with carried "
        f"filter state (start: {args.initial}); reference and time unchanged; wrote {args.output}"
    )
    if args.json:
        emit_json(
            {
                "record": str(args.record),
                "dcm": str(args.dcm),
                "output": str(args.output),
                "samples": record.n_samples,
                "blocks": n_blocks,
                "block_samples": args.block_samples,
                "initial": args.initial,
                "sample_interval_s": record.sample_interval_s,
                "dcm_order": dcm.order,
                "what": what,
            }
        )
    else:
        sys.stdout.write(what + "\n")
    return 0


def register(subparsers: Any) -> None:
    """Add the `dcm` and `compensate` sub-commands."""
    p = subparsers.add_parser(
        "dcm",
        help="design a dynamic compensation model (DCM) from a model or its poles",
        description="Design the DCM of the paper's Eqs. (13)-(25): zeros at the model poles, new poles "
        "from the response-time ratio r and damping zeta_e, unit DC gain. Poles as 0.974+0.1396j, both "
        "members of each conjugate pair; a list starting with '-' needs --poles=-0.5,…",
    )
    src = p.add_argument_group("model (one of)")
    src.add_argument("--model", metavar="MODEL.json", help="model file from `hopkinson identify -o`")
    src.add_argument("--poles", metavar="P,P,...", help="the model's discrete poles, comma-separated")
    p.add_argument("--sample-interval", type=float, metavar="S", help="sample interval in s (with --poles)")
    p.add_argument("--ratio", type=float, required=True, metavar="R", help="response-time ratio r (> 0)")
    p.add_argument("--damping", type=float, required=True, metavar="Z", help="damping ratio zeta_e of the new poles, (0, 1]")
    p.add_argument("--extra-poles", metavar="P,...", help="additional DCM poles (e.g. 0.6+0.1j,0.6-0.1j)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--output", metavar="DCM.json", help="write the DCM (and the analysis) to this file")
    p.set_defaults(func=run_dcm)

    c = subparsers.add_parser(
        "compensate",
        help="apply a DCM to a record's response column (streaming)",
        description="Filter the response column of RECORD with the DCM, block by block with carried "
        "state, and write a record with the same time and reference columns.",
    )
    c.add_argument("record", metavar="RECORD", help="two-channel record (CSV or NPZ)")
    c.add_argument("--dcm", required=True, metavar="DCM.json", help="DCM file from `hopkinson dcm -o`")
    c.add_argument("-o", "--output", required=True, metavar="OUT", help="output record (.csv or .npz)")
    c.add_argument("--block-samples", type=int, default=DEFAULT_BLOCK_SAMPLES, metavar="N", help="samples per block")
    c.add_argument(
        "--initial",
        choices=("steady", "rest"),
        default="steady",
        help="filter start: 'steady' (settled on the first sample: no start-up transient from an offset; "
        "default) or 'rest' (zero state)",
    )
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_compensate)
