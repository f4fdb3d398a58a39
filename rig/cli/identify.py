"""`hopkinson identify`: the accelerometer's dynamic model from a two-channel record, with its
uncertainty.

    hopkinson identify RECORD [--max-order N] [--order n] [--sample-rate HZ]
                      [--draws N] [--no-uncertainty] [--seed N] [--sine SINE.csv] [--json] [-o model.json]

RECORD is a CSV (time_s,reference,response) or NPZ with the same keys. The JSON (printed
with --json, written by -o) is the model file `hopkinson dcm --model` reads: sample interval,
order, a, b, poles and zeros as [re, im] pairs, DC gain, loss by order, FBSD (Hz) and the
paper's Table-1 pole analysis, the fit details, FBSD edges beyond the supported band as
bounds (`fbsd_bounds`), and the Monte Carlo uncertainty (`uncertainty`, analysis.uncertainty).
The text output shows each uncertain figure as value ± U, U the half-width of its 95 %
coverage interval (k ≈ 2).

--sine SINE.csv fits one model to the record and a sinusoidal calibration of the same sensor
(analysis.sine_joint), each weighed by its own uncertainty; the JSON's `sine_joint` and the text
give their consistency (E_n per point, the verdict, the sine's level ÷ the shock's).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import TYPE_CHECKING, Any

from hopkinson.analysis.errors import AnalysisError
from hopkinson.rig.cli.main import emit_json

if TYPE_CHECKING:
    from hopkinson.analysis.identify import Identification
    from hopkinson.analysis.shot_analysis import ModelWithUncertainty

# The command's flags by AnalysisOptions option, so a bad value is named as it was typed.
FLAGS = {"max_order": "--max-order", "order": "--order", "sample_rate_hz": "--sample-rate", "draws": "--draws",
         "seed": "--seed"}


def identification_report(fitted: ModelWithUncertainty, source: str, warnings: list[str]) -> dict[str, Any]:
    """The JSON object of `hopkinson identify` (also what -o writes): the model file of
    `fitted` (ModelWithUncertainty.to_dict) from `source`, with `warnings` in place of its own."""
    return {"source": source, **fitted.to_dict(), "warnings": list(warnings)}


def _figure_text(data: Any, scale: float = 1.0, unit: str = "", digits: int = 6) -> str:
    from hopkinson.analysis.estimate import Estimate

    figure = Estimate.of(data)
    return figure.format(scale, digits, unit) if figure is not None else "—"


def _summary(report: dict[str, Any], result: Identification) -> str:
    """A short human-readable account of the identification and its uncertainty."""
    from hopkinson.analysis.key_figures import ORDER_SELECTION_TEXT, KeyFigures
    from hopkinson.analysis.modes import RESONANCE_MAX_DAMPING, ModeKind, claimed

    unc = report.get("uncertainty") or {}
    figures = KeyFigures.from_results({"model": report, "identification": report, "fbsd_hz": report["fbsd_hz"],
                                       "fbsd_bounds": report["fbsd_bounds"], "uncertainty": unc})
    how = ORDER_SELECTION_TEXT.get(result.order_selection, result.order_selection)
    stability = result.order_evidence.stability
    if stability is not None and str(result.order) in stability.fraction_by_order:
        how += f", chosen in {stability.fraction_by_order[str(result.order)]:.0%} of {stability.draws} noise draws"
    dt = result.sample_interval_s
    lines = [
        f"{report['source']}: order {result.order} ({how}), fit {result.fit_percent:.2f} %, sample interval "
        f"{dt:g} s, delay {result.delay_samples:.3g} samples ({result.delay_samples * dt * 1e6:.3g} µs)",
    ]
    if result.supported_band_hz:
        lo, hi = result.supported_band_hz
        lines.append(f"  supported band (the excitation's): {lo / 1e3:.4g}–{hi / 1e3:.4g} kHz")
    main = result.main_mode
    for mode in result.modes:
        pole = mode.pole_z
        sign = "±" if mode.kind == ModeKind.COMPLEX else ""
        f_n, zeta = mode.natural_frequency_hz, mode.damping_ratio
        if f_n is None or zeta is None:
            where = "at the origin"
        elif main is not None and mode.pole == main.pole and figures.natural_frequency_hz is not None:
            where = (f"f_n = {figures.natural_frequency_hz.format(1e3, unit='kHz')}, "
                     f"ζ = {figures.damping_ratio.format() if figures.damping_ratio else zeta}  (main mode)")
        else:
            where = f"f_n = {f_n / 1e3:.4g} kHz, ζ = {zeta:.4g}"
        note = ("" if claimed(mode) else ", nearly cancelled by a zero (a doublet): not claimed"
                if mode.cancelled else ", outside the supported band: not claimed" if not mode.supported
                else f", damped ζ > {RESONANCE_MAX_DAMPING:g}: no resonance, not claimed" if mode.kind == ModeKind.COMPLEX
                else "")
        lines.append(f"  pole {pole.real:.6f} {sign}{abs(pole.imag):.6f}j  ({mode.kind}{note}): {where}")
    lines.append(f"  FBSD: ±5 % up to {figures.fbsd_text('5')}, ±10 % up to {figures.fbsd_text('10')}")
    lines.append(f"  DC gain {figures.sensitivity.format()} (response units per m/s²)")
    if unc.get("shock_sensitivity"):
        lines.append(f"  shock sensitivity (ISO 16063-13 peak ratio) {_figure_text(unc['shock_sensitivity'])}")
    nmp = report.get("nonminimum_phase_zeros") or []
    if nmp:
        zeros = ", ".join(f"{re:.4g}{im:+.4g}j" for re, im in nmp)
        lines.append(f"  zeros outside the unit circle (non-minimum phase: never inverted by a DCM): {zeros}")
    if unc:
        top = sorted((b for b in unc.get("budget", []) if b.get("u_rel")), key=lambda b: -b["u_rel"])[:4]
        parts = ", ".join(f"{b['source']} {100 * b['u_rel']:.2g} %" for b in top)
        lines.append(f"  uncertainty: {unc['method']}, {unc['draws']} draws, ± = half-width of the 95 % interval "
                     f"(k ≈ 2); DC gain budget: {parts}")
    if result.sine_joint is not None:
        lines += sine_joint_lines(result.sine_joint)
    losses = ", ".join(f"{n}: {v:.4g}" for n, v in enumerate(result.loss_by_order, start=1) if math.isfinite(v))
    lines.append(f"  cost V by order (errors-in-variables, ≈ bins when right): {losses}")
    for warning in report["warnings"]:
        lines.append(f"  warning: {warning}")
    return "\n".join(lines)


def sine_joint_lines(joint: Any) -> list[str]:
    """The joint fit's consistency in words (analysis.sine_joint.SineJoint)."""
    lines = [f"  fitted with the sine calibration {joint.sine.source}: {joint.verdict()}",
             f"  {joint.gain_text()}; skew of the shock's channels as the sine sees it {joint.skew_s * 1e6:.3g} µs"]
    worst = sorted(range(joint.e_n.size), key=lambda i: -joint.e_n[i])[:3]
    parts = ", ".join(f"{joint.sine.frequency_hz[i] / 1e3:.4g} kHz {joint.error_mag_pct[i]:+.2f} % "
                      f"{joint.error_phase_deg[i]:+.2f}° (E_n {joint.e_n[i]:.2g})" for i in sorted(worst))
    lines.append(f"  largest E_n: {parts}")
    return lines


def _checked_params(args: argparse.Namespace) -> Any:
    """The analysis options of the command line, checked; a bad one is named by its flag."""
    from hopkinson.analysis.options import AnalysisOptions

    values: dict[str, Any] = {"max_order": args.max_order, "order": args.order, "draws": args.draws,
                              "seed": args.seed, "uncertainty": not args.no_uncertainty}
    if args.sample_rate is not None:
        values["sample_rate_hz"] = args.sample_rate
    try:
        return AnalysisOptions.from_options(**values)
    except AnalysisError as exc:
        raise named_by_flag(exc, FLAGS) from None


def named_by_flag(exc: AnalysisError, flags: dict[str, str]) -> AnalysisError:
    """The AnalysisOptions check's error with each option named by the command's flag."""
    text = str(exc)
    for option, flag in flags.items():
        text = text.replace(f"analysis option {option}:", f"{flag}:")
    return AnalysisError(text)


def run_identify(args: argparse.Namespace) -> int:
    """Identify the model of RECORD with its uncertainty; print a summary or the JSON; optionally
    write the JSON (never over the record or a shot file; atomically)."""
    from hopkinson.analysis.records import read_record
    from hopkinson.analysis.shot_analysis import identify_with_uncertainty
    from hopkinson.fileio import atomic_write, check_output_path

    params = _checked_params(args)
    out = check_output_path(args.output, [args.record] + ([args.sine] if args.sine else []), what="model file") if args.output else None
    record = read_record(args.record)
    from hopkinson.analysis.flat_top import flat_top_warnings

    clipped = flat_top_warnings(record, str(args.record))  # a table file has no full scale to judge by
    if args.method == "paper":
        return _run_paper(args, params, record, out, clipped)
    sine = None
    if args.sine:
        from hopkinson.analysis.sine_comparison import read_sine_calibration

        sine = read_sine_calibration(args.sine)
    try:
        fitted = identify_with_uncertainty(record, params, None, sine)
    except AnalysisError as exc:
        raise AnalysisError(f"{args.record}{' with ' + args.sine if sine else ''}: {exc}") from None
    result = fitted.identification
    report = identification_report(fitted, str(args.record), clipped + fitted.warnings)
    if out is not None:
        try:
            atomic_write(out, json.dumps(report, indent=2, allow_nan=False) + "\n")
        except OSError as exc:
            raise AnalysisError(f"{out}: cannot write the model file ({exc.strerror})") from None
    if args.json:
        emit_json(report)
    else:
        sys.stdout.write(_summary(report, result) + "\n")
        if args.explain:
            sys.stdout.write(result.trail.text() + "\n")
        if out is not None:
            sys.stdout.write(f"model written to {out}\n")
    return 0


def _run_paper(args: argparse.Namespace, params: Any, record: Any, out: Any, clipped: list[str]) -> int:
    """`--method paper`: the paper's section 2.1, literally (analysis.paper_method); `clipped`:
    the record's flat-top warnings."""
    from hopkinson.analysis.paper_method import paper_identify
    from hopkinson.analysis.response import fbsd_hz
    from hopkinson.fileio import atomic_write

    if args.sine:
        raise AnalysisError("--sine: the paper's method fits the shock alone (use the default method)")
    try:
        result = paper_identify(record, max_order=params.max_order, order=params.order,
                                sample_rate_hz=params.sample_rate_hz)
    except AnalysisError as exc:
        raise AnalysisError(f"{args.record}: {exc}") from None
    model = result.model
    report = result.to_dict() | {"record": str(args.record), "fbsd_hz": fbsd_hz(model),
                                 "poles": [[p.real, p.imag] for p in model.poles],
                                 "warnings": clipped + list(result.warnings)}
    if out is not None:
        atomic_write(out, json.dumps(report, indent=2, allow_nan=False) + "\n")
    if args.json:
        emit_json(report)
        return 0
    f = report["fbsd_hz"]
    lines = [f"{args.record}: the paper's method: order {model.order} ({result.order_rule}; inflexions of "
             f"||g2||^2 at {', '.join(map(str, result.inflexions)) or 'none'}), Eq. 12 prefilter "
             f"{result.iterations} pass(es), {'converged' if result.converged else 'NOT converged'}",
             f"  FBSD: ±5 % up to {f['5'] / 1e3:.4g} kHz, ±10 % up to {f['10'] / 1e3:.4g} kHz",
             "  poles: " + ", ".join(f"{p.real:.6f}{p.imag:+.6f}j (|p| {abs(p):.5f})" for p in model.poles),
             "  no uncertainty: the paper's method gives none"]
    lines += [f"  warning: {w}" for w in report["warnings"]]
    sys.stdout.write("\n".join(lines) + "\n")
    if out is not None:
        sys.stdout.write(f"model written to {out}\n")
    return 0


def register(subparsers: Any) -> None:
    """Add the `identify` sub-command."""
    from hopkinson.analysis.options import declared

    p = subparsers.add_parser(
        "identify",
        help="identify the accelerometer's discrete model, with its uncertainty, from a two-channel record",
        description="Identify A(d^-1) y = B(d^-1) u(k - delay) from RECORD (CSV time_s,reference,response or NPZ): "
        "resample to the analysis rate, normalise both channels, measure their noise, fit every order by an "
        "errors-in-variables output-error fit weighted to the band the excitation supports (causal fractional "
        "delay fitted with it), choose the order by a test that is stable under the record's own noise, and give "
        "every key figure its GUM Supplement 1 (Monte Carlo) uncertainty.",
    )
    p.add_argument("record", metavar="RECORD", help="two-channel record (CSV or NPZ)")
    p.add_argument("--max-order", type=int, default=declared("max_order"), metavar="N",
                   help="largest order tried (default %(default)s)")
    p.add_argument("--order", type=int, metavar="n", help="fit exactly this order instead of choosing it")
    p.add_argument(
        "--sample-rate",
        type=float,
        metavar="HZ",
        # None: analysis.options.DEFAULT_ANALYSIS_RATE_HZ (resolved by AnalysisOptions)
        help="analysis rate: a record sampled faster is low-pass filtered and resampled (default 1e6)",
    )
    p.add_argument("--draws", type=int, metavar="N",
                   help="Monte Carlo draws of the uncertainty (default 400: stable 95 %% intervals)")
    p.add_argument("--no-uncertainty", action="store_true", help="skip the uncertainty (the figures alone)")
    p.add_argument("--seed", type=int, metavar="N", help="seed of the Monte Carlo draws (default: fresh)")
    p.add_argument("--sine", metavar="SINE.csv",
                   help="fit one model to the record and this sinusoidal calibration of the same sensor (columns "
                   "frequency_hz,magnitude,phase_deg, optional u_magnitude_rel,u_phase_deg), and report their "
                   "consistency")
    p.add_argument("--method", choices=("default", "paper"), default="default",
                   help="default: the method above; paper: the paper's section 2.1 as written (ARX by QR, the order "
                   "at the second inflexion of ||g2||^2, Eq. 12's prefilter iterated; no uncertainty), to compare")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--explain", action="store_true",
                   help="also print how each stage decided: noise and where measured, band, V by order, model "
                   "error, what was claimed or not and why")
    p.add_argument("-o", "--output", metavar="MODEL.json", help="write the model JSON (read by `hopkinson dcm --model`)")
    p.set_defaults(func=run_identify)
