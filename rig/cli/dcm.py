"""`hopkinson dcm` (design a dynamic compensation model) and `hopkinson compensate` (apply one).

    hopkinson dcm (--model model.json | --poles P,P,… --sample-interval S) [--ratio auto|R]
                  [--damping Z] [--widening auto|W] [--noise-gain-limit G] [--band-limit auto|off|HZ]
                  [--extra-poles P,…] [--record RECORD] [--json] [-o dcm.json]
    hopkinson compensate RECORD --dcm dcm.json -o out.csv [--causal] [--force]
                  [--block-samples N] [--initial steady|rest] [--json]

The design (analysis.dcm_design) cancels only the modes the shot supports, chooses r
(analysis.dcm_ratio: sized to the record's pulse with --record, else to the supported band, or
for --widening W; within the noise-gain limit; or takes --ratio), band-limits at the top of the
supported band and reports the latency; --record checks it on the shot it came from
(analysis.compensation). `compensate` brings the record to the DCM's rate, removes the
latency (unless --causal) and refuses a DCM marked not recommended (unless --force).

Poles are written like 0.974+0.1396j (or …i), every pole listed, both members of a
conjugate pair. A list that starts with a minus sign needs the = form: --poles=-0.5,0.3.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.analysis.errors import AnalysisError
from hopkinson.fileio import UnsafeOutputError, atomic_open, atomic_write, check_output_path
from hopkinson.rig.cli.main import emit_json

if TYPE_CHECKING:
    import numpy as np

    from hopkinson.analysis.dcm import DCM
    from hopkinson.analysis.dcm_design import DcmDesign, ShotSupport
    from hopkinson.analysis.model import DiscreteModel
    from hopkinson.analysis.options import AnalysisOptions
    from hopkinson.analysis.records import Record

DEFAULT_BLOCK_SAMPLES = 65_536
# The command's flags by analysis option, so a bad value is named as it was typed.
DCM_FLAGS = {"dcm_ratio": "--ratio", "dcm_damping": "--damping", "dcm_widening": "--widening",
             "dcm_noise_gain_limit": "--noise-gain-limit", "dcm_band_limit_hz": "--band-limit",
             "extra_poles": "--extra-poles"}


def _checked_output(output: str | None, inputs: list[str]) -> Path | None:
    """check_output_path as one clear AnalysisError (exit 2) before any work."""
    if output is None:
        return None
    try:
        return check_output_path(output, [i for i in inputs if i])
    except UnsafeOutputError as exc:
        raise AnalysisError(str(exc)) from None


def _load_support(path: str, record: Record | None) -> tuple[DiscreteModel, ShotSupport]:
    """The model of a model JSON (`identify -o`, a shot's results) and what it says the shot
    supports (with its record: also its pulse, which the automatic ratio sizes the DCM to, and
    where the response stands above its noise, as the shot analysis judges it); any malformed
    content is one clear message."""
    from hopkinson.analysis.dcm_design import ShotSupport, pulse_of, response_band_top_hz
    from hopkinson.analysis.model import DiscreteModel, load_json_object

    data = load_json_object(path, "model")
    try:
        model = DiscreteModel.from_dict(data.get("model", data), source=str(path))
        ident = data.get("identification", data)
        ident = ident if isinstance(ident, dict) else {}
        support = ShotSupport.from_dict(ident, model)
        rms = (ident.get("noise") or {}).get("response_rms")
        if record is not None:
            record = _at_rate(record, model)
            support = replace(support, pulse=pulse_of(record))
            if isinstance(rms, (int, float)) and rms > 0:
                support = replace(support, response_band_top_hz=response_band_top_hz(record, model, float(rms)))
    except AnalysisError as exc:
        raise AnalysisError(str(exc) if str(exc).startswith(str(path)) else f"{path}: {exc}") from None
    except (TypeError, ValueError, IndexError, KeyError) as exc:
        raise AnalysisError(f"{path}: not a valid model file ({exc})") from None
    if model.a.ndim != 1 or model.b.ndim != 1:
        raise AnalysisError(f"{path}: 'a' and 'b' must be flat lists of numbers")
    if model.order < 1:
        raise AnalysisError(f"{path}: the model has no poles (a = {list(model.a)}); nothing to compensate")
    return model, support


def number_or_word(text: str, option: str, words: dict[str, float | None], what: str) -> float | None:
    """A positive finite number, or one of `words` (its value); AnalysisError naming the option."""
    word = text.strip().lower()
    if word in words:
        return words[word]
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise AnalysisError(f"{option}: {' or '.join(repr(w) for w in words)} or {what}, got {text!r}")
    return value


def _poly_text(coeffs: np.ndarray) -> str:
    n = len(coeffs) - 1
    terms = []
    for i, c in enumerate(coeffs):
        power = n - i
        z = "" if power == 0 else ("z" if power == 1 else f"z^{power}")
        terms.append(f"{c:+.6g}{'·' if z else ''}{z}")
    return " ".join(terms).lstrip("+")


def _print_design(result: dict[str, Any], dcm: DCM) -> None:
    from hopkinson.analysis.pole_checks import format_complex

    out = sys.stdout
    out.write(f"Model: {result['source']} (sample interval {dcm.sample_interval_s:g} s)\n")
    out.write("Pole analysis (paper Table 1; response time in samples):\n")
    out.write(f"  {'pole':<26}{'T_r':>12}{'r_i':>10}\n")
    for row in result["pole_analysis"]:
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.2f}"
        out.write(f"  {format_complex(complex(*row['pole'])):<26}{row['response_time_samples']:>12.2f}{ratio:>10}\n")
    d = dcm.design
    for skipped in d.get("skipped_poles", []):
        out.write(f"  not cancelled: {format_complex(complex(*skipped['pole']))}: {skipped['reason']}\n")
    if "ratio" in d:
        out.write(
            f"DCM: r = {d['ratio']:g}, zeta_e = {d['damping']:g}: target response time "
            f"{d['target_response_time_samples']:.3f} samples; designed poles "
            f"{', '.join(format_complex(complex(*p)) for p in d['designed_poles'])}\n"
        )
        if d["extra_poles"]:
            out.write(f"  extra poles: {', '.join(format_complex(complex(*p)) for p in d['extra_poles'])}\n")
        if d["origin_poles"]:
            out.write(
                f"  {d['origin_poles']} pole(s) placed at z = 0 to make the DCM causal: "
                f"its output lags by {d['origin_poles']} sample(s); the magnitude is as designed\n"
            )
    r = result["dcm"]
    band = r.get("band_limit_hz")
    taps = 0 if dcm.fir is None else dcm.fir.size
    out.write("  band limit: " + (f"{band / 1e3:.4g} kHz cut-off (a linear-phase FIR of {taps} taps, 4th-order "
                                  f"Butterworth magnitude; {r.get('band_limit_reason')})\n"
                                  if band else f"none ({r.get('band_limit_reason', 'not asked')})\n"))
    out.write(f"  num: {_poly_text(dcm.pole_zero_num)}\n  den: {_poly_text(dcm.pole_zero_den)}\n"
              f"  gain K = {dcm.gain:.6g}"
              + (f", then the band limit's {taps} taps (`fir` in the JSON; num/den there include them)" if taps else "")
              + " (G(1) = 1)\n")
    limit = r.get("noise_gain_limit")
    out.write(f"  noise gain {r['noise_gain']:.3g} (white-noise RMS at the analysis rate"
              + (f"; limit {limit:g})\n" if limit is not None else ")\n"))
    out.write(f"  latency {r['latency_s'] * 1e6:.3f} µs (removed by `hopkinson compensate` unless --causal)\n")
    target, reached = r.get("target_widening"), r.get("reached_widening")
    if reached is not None:
        aim = f"aimed for ×{target:g}, " if target is not None else ""
        out.write(f"  widening of the ±5 % band: {aim}reached ×{reached:.2f}\n")
    if r.get("widening_note"):
        out.write(f"  note: {r['widening_note']}\n")
    for note in r.get("notes", []):
        if note != r.get("widening_note"):
            out.write(f"  note: {note}\n")
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
    check = r.get("check")
    if check:
        rms, peak = check["rms_error_pct"], check["peak_error_pct"]
        out.write(f"Check on {result.get('record')}: RMS error over the pulse {rms['uncompensated']:.3g} % -> "
                  f"{rms['compensated']:.3g} %, peak error {peak['uncompensated']:+.3g} % -> "
                  f"{peak['compensated']:+.3g} % (of the reference peak)\n")
    if r.get("recommended") is False:
        out.write(f"NOT RECOMMENDED: {r.get('not_recommended_reason')}\n")
    elif r.get("recommended") is True:
        out.write("Recommended: compensation improves the record it was checked on\n")


def _at_rate(record: Record, model: DiscreteModel) -> Record:
    from hopkinson.analysis.compensation import to_rate

    return to_rate(record, 1.0 / model.sample_interval_s)[0]


def _design(args: argparse.Namespace, record: Record | None
            ) -> tuple[np.ndarray, DcmDesign, DiscreteModel | None, str]:
    """(poles shown in the pole analysis, the design, the model to report or None, source)."""
    from hopkinson.analysis.dcm_design import ShotSupport, poles_only_model
    from hopkinson.analysis.options import DCM_OPTIONS, AnalysisOptions
    from hopkinson.analysis.pole_checks import check_conjugate_pairs, parse_poles
    from hopkinson.rig.cli.identify import named_by_flag

    if (args.model is None) == (args.poles is None):
        raise AnalysisError("dcm: give either --model FILE or --poles P,P,… (with --sample-interval)")
    try:  # the model's own rate bounds the band limit (the design checks it)
        options = AnalysisOptions(
            sample_rate_hz=None,
            dcm_ratio=number_or_word(args.ratio, "--ratio", {"auto": None}, "a positive number"),
            dcm_damping=args.damping,
            dcm_widening=number_or_word(args.widening, "--widening", {"auto": None}, "a number above 1"),
            dcm_noise_gain_limit=args.noise_gain_limit,
            dcm_band_limit_hz=number_or_word(args.band_limit, "--band-limit", {"auto": None, "off": 0.0},
                                             "a positive frequency in Hz"),
            extra_poles=tuple(parse_poles(args.extra_poles, "--extra-poles")) if args.extra_poles else (),
        )
        options.check(DCM_OPTIONS)
    except AnalysisError as exc:
        raise named_by_flag(exc, DCM_FLAGS) from None
    if args.model is not None:
        if args.sample_interval is not None:
            raise AnalysisError("dcm: --sample-interval goes with --poles; a model file carries its own")
        model, support = _load_support(args.model, record)
        return model.poles, _designed(support, options, args.model), model, str(args.model)
    if args.sample_interval is None:
        raise AnalysisError("dcm: --poles needs --sample-interval S (seconds, e.g. 1e-6)")
    if not (math.isfinite(args.sample_interval) and args.sample_interval > 0):
        raise AnalysisError(f"dcm: --sample-interval must be a positive number of seconds, got {args.sample_interval}")
    poles = parse_poles(args.poles, "--poles")
    check_conjugate_pairs(poles, "--poles")
    support = ShotSupport(poles_only_model(poles, args.sample_interval))
    return poles, _designed(support, options, "--poles"), None, "--poles"


def _designed(support: ShotSupport, options: AnalysisOptions, source: str) -> DcmDesign:
    """design_compensation, refusing a DCM with nothing to cancel (one line naming why)."""
    from hopkinson.analysis.dcm_design import design_compensation

    result = design_compensation(support, options)
    if result.poles.cancelled.size == 0:
        why = "; ".join(f"{complex(*s['pole']):.6g}: {s['reason']}" for s in result.poles.skipped)
        raise AnalysisError(f"{source}: nothing to compensate (no pole the DCM may cancel: {why})")
    return result


def run_dcm(args: argparse.Namespace) -> int:
    """Design the DCM and report it (text or --json); -o writes the DCM file atomically."""
    from hopkinson.analysis.compensation import check_compensation, recommendation, to_rate
    from hopkinson.analysis.dcm_design import design_report
    from hopkinson.analysis.records import read_record

    if args.record is not None and args.model is None:
        raise AnalysisError("dcm: --record needs --model (the check compares the model's compensation with the record)")
    output = _checked_output(args.output, [args.model, args.record])
    raw = None if args.record is None else read_record(args.record)
    poles, design, model, source = _design(args, raw)
    result = design_report(poles, design.dcm, model, source, design)
    check = None
    if raw is not None and model is not None:
        record, resampled = to_rate(raw, 1.0 / model.sample_interval_s)
        try:
            check = check_compensation(record, model, design.dcm, model.delay_samples)
        except AnalysisError as exc:
            raise AnalysisError(f"{args.record}: {exc}") from None
        result["record"] = str(args.record)
        result["record_resampled"] = resampled
    recommended, reason = recommendation(design, check)
    result["dcm"].update({"recommended": recommended, "not_recommended_reason": reason,
                          "check": None if check is None else check.to_dict()})
    try:
        text = json.dumps(result, indent=2, allow_nan=False) + "\n"
    except ValueError:
        raise AnalysisError(f"{source}: the DCM's figures are not all finite numbers (a pole on the unit circle?); "
                            "nothing written") from None
    if output is not None:
        atomic_write(output, text)
        result["output"] = str(output)
    if args.json:
        emit_json(result)
    else:
        _print_design(result, design.dcm)
        if output is not None:
            sys.stdout.write(f"wrote {output}\n")
    return 0


def run_compensate(args: argparse.Namespace) -> int:
    """Apply a DCM to a record's response, streamed block by block, and write the result."""
    from hopkinson.analysis.compensation import to_rate
    from hopkinson.analysis.dcm import DCM
    from hopkinson.analysis.dcm_stream import DcmStream
    from hopkinson.analysis.model import load_json_object
    from hopkinson.analysis.records import read_record

    if args.block_samples < 1:
        raise AnalysisError(f"compensate: --block-samples must be at least 1, got {args.block_samples}")
    output = _checked_output(args.output, [args.record, args.dcm])
    data = load_json_object(args.dcm, "DCM")
    fields = data.get("dcm", data)
    dcm = DCM.from_dict(fields, source=str(args.dcm))
    if isinstance(fields, dict) and fields.get("recommended") is False and not args.force:
        raise AnalysisError(
            f"{args.dcm}: this DCM is marked not recommended ({fields.get('not_recommended_reason')}); "
            "--force applies it anyway"
        )
    record, resampled = to_rate(read_record(args.record), 1.0 / dcm.sample_interval_s)
    if not args.causal and abs(dcm.latency_s) >= record.n_samples * record.sample_interval_s:
        raise AnalysisError(
            f"{args.dcm}: the DCM's latency ({dcm.latency_s:g} s) is as long as the record {args.record} "
            f"({record.n_samples * record.sample_interval_s:g} s): nothing of it would remain once aligned"
        )
    stream = DcmStream(dcm, args.initial, align=not args.causal)
    n, step = record.n_samples, args.block_samples
    blocks = -(-n // step)
    _write_stream(output, record, (stream.process(record.response[i : i + step]) for i in range(0, n, step)),
                  stream.flush)
    latency = dcm.latency_s
    timing = (f"latency {latency * 1e6:.3f} µs kept (--causal: the output lags the reference)" if args.causal
              else f"latency {latency * 1e6:.3f} µs removed (time-aligned with the reference)")
    what = (
        f"compensated the response column of {args.record} ({n} samples"
        + (f", {resampled}" if resampled else "")
        + f") with the order-{dcm.order} DCM of {args.dcm}, streamed in {blocks} block(s) of up to {step} samples "
        f"with carried filter state (start: {args.initial}); {timing}; reference and time unchanged; wrote {output}"
    )
    if args.json:
        emit_json({
            "record": str(args.record), "dcm": str(args.dcm), "output": str(output), "samples": n,
            "blocks": blocks, "block_samples": step, "initial": args.initial,
            "sample_interval_s": record.sample_interval_s, "resampled": resampled, "dcm_order": dcm.order,
            "latency_s": latency, "latency_removed": not args.causal,
            "recommended": fields.get("recommended") if isinstance(fields, dict) else None, "what": what,
        })
    else:
        sys.stdout.write(what + "\n")
    return 0


def _write_stream(output: Path, record: Any, parts: Any, flush: Any) -> None:
    """Write time, reference and the compensated response as the blocks come (CSV rows block
    by block; NPZ at the end), atomically: an error leaves no file."""
    import numpy as np

    from hopkinson.analysis.records import RECORD_KEYS, header_cell

    units = {"time_s": "s", "reference": "m/s^2", "response": getattr(record, "response_unit", None)}
    if output.suffix.lower() == ".npz":
        response = np.concatenate([*parts, flush()])
        with atomic_open(output, "wb") as fh:
            np.savez(fh, time_s=record.time_s, reference=record.reference, response=response,
                     **{f"{k}_unit": np.array(u) for k, u in units.items() if u})
        return
    with atomic_open(output, "w", newline="") as fh:
        fh.write(",".join(header_cell(k, units[k]) for k in RECORD_KEYS) + "\n")
        done = 0
        for block in _chain(parts, flush):
            rows = np.column_stack([record.start_time_s + record.sample_interval_s * np.arange(done, done + block.size),
                                    record.reference[done : done + block.size], block])
            np.savetxt(fh, rows, delimiter=",", fmt="%.10g")
            done += block.size


def _chain(parts: Any, flush: Any) -> Any:
    """The blocks, then the stream's held-back tail."""
    yield from parts
    yield flush()


def register(subparsers: Any) -> None:
    """Add the `dcm` and `compensate` sub-commands."""
    from hopkinson.analysis.options import declared

    p = subparsers.add_parser(
        "dcm",
        help="design a dynamic compensation model (DCM) from a model or its poles",
        description="Design the DCM of the paper's Eqs. (13)-(25) from what the shot supports: zeros at the "
        "supported model poles, new poles from the response-time ratio r (auto: the r that widens the ±5 %% band "
        "sized to the --record's pulse, or to the supported band, or for --widening; within --noise-gain-limit) "
        "and damping zeta_e, a band limit at the top of the supported "
        "band, unit DC gain; reports noise gain and latency. Poles as 0.974+0.1396j, both members of each "
        "conjugate pair; a list starting with '-' needs --poles=-0.5,…",
    )
    src = p.add_argument_group("model (one of)")
    src.add_argument("--model", metavar="MODEL.json", help="model file from `hopkinson identify -o`")
    src.add_argument("--poles", metavar="P,P,...", help="the model's discrete poles, comma-separated")
    p.add_argument("--sample-interval", type=float, metavar="S", help="sample interval in s (with --poles)")
    p.add_argument("--ratio", default="auto", metavar="auto|R",
                   help="response-time ratio r (> 0), or 'auto' (default): chosen as --widening says")
    p.add_argument("--damping", type=float, default=declared("dcm_damping"), metavar="Z",
                   help="damping ratio zeta_e of the new poles, (0, 1] (default %(default)s)")
    p.add_argument("--widening", default="auto", metavar="auto|W",
                   help="auto ratio: 'auto' (default: the band the --record's pulse needs, else the widest the "
                   "supported band allows) or widen the model's ±5 %% band W times (W > 1)")
    p.add_argument("--noise-gain-limit", type=float, default=declared("dcm_noise_gain_limit"), metavar="G",
                   help="auto ratio: largest white-noise RMS gain allowed (default %(default)s)")
    p.add_argument("--band-limit", default="auto", metavar="auto|off|HZ",
                   help="low-pass cut-off: 'auto' (default: the top of the band the shot supports), 'off' or Hz")
    p.add_argument("--extra-poles", metavar="P,...", help="additional DCM poles (e.g. 0.6+0.1j,0.6-0.1j)")
    p.add_argument("--record", metavar="RECORD", help="check the DCM on this record (the shot of the model)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--output", metavar="DCM.json", help="write the DCM (and the analysis) to this file")
    p.set_defaults(func=run_dcm)

    c = subparsers.add_parser(
        "compensate",
        help="apply a DCM to a record's response column (streaming)",
        description="Filter the response column of RECORD with the DCM, block by block with carried "
        "state, and write a record with the same time and reference columns. A record at another rate is "
        "brought to the DCM's first; the DCM's latency is removed (time-aligned with the reference) unless "
        "--causal. A DCM marked not recommended is refused unless --force.",
    )
    c.add_argument("record", metavar="RECORD", help="two-channel record (CSV or NPZ)")
    c.add_argument("--dcm", required=True, metavar="DCM.json", help="DCM file from `hopkinson dcm -o`")
    c.add_argument("-o", "--output", required=True, metavar="OUT", help="output record (.csv or .npz)")
    c.add_argument("--causal", action="store_true", help="keep the latency (a causal, real-time output)")
    c.add_argument("--force", action="store_true", help="apply a DCM even if it is marked not recommended")
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
