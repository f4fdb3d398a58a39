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

# The command's flags by AnalysisParams option, so a bad value is named as it was typed.
FLAGS = {"max_order": "--max-order", "order": "--order", "sample_rate_hz": "--sample-rate", "draws": "--draws",
         "seed": "--seed"}


def identification_report(result: Identification, source: str, uncertainty: dict[str, Any] | None = None,
                          warnings: list[str] | None = None) -> dict[str, Any]:
    """The JSON object of `hopkinson identify` (also what -o writes)."""
    from hopkinson.analysis.response import fbsd_bounds, fbsd_hz, pole_analysis

    report = {"source": source, **result.to_dict()}
    report["fbsd_hz"] = fbsd_hz(result.model)
    report["fbsd_bounds"] = fbsd_bounds(report["fbsd_hz"], result.supported_band_hz)
    report["pole_analysis"] = pole_analysis(result.poles)
    report["uncertainty"] = uncertainty
    report["warnings"] = list(warnings if warnings is not None else result.warnings)
    return report


def _figure_text(data: Any, scale: float = 1.0, unit: str = "", digits: int = 6) -> str:
    from hopkinson.analysis.key_figures import Figure

    figure = Figure.of(data)
    return figure.format(scale, digits, unit) if figure is not None else "—"


def _summary(report: dict[str, Any], result: Identification) -> str:
    """A short human-readable account of the identification and its uncertainty."""
    from hopkinson.analysis.key_figures import ORDER_SELECTION_TEXT, KeyFigures
    from hopkinson.analysis.modes import RESONANCE_MAX_DAMPING, ModeKind, claimed

    unc = report.get("uncertainty") or {}
    figures = KeyFigures.from_results({"model": report, "identification": report, "fbsd_hz": report["fbsd_hz"],
                                       "fbsd_bounds": report["fbsd_bounds"], "uncertainty": unc})
    how = ORDER_SELECTION_TEXT.get(result.order_selection, result.order_selection)
    stability = (result.order_evidence.get("stability") or {}).get("fraction_by_order") or {}
    if str(result.order) in stability:
        how += f", chosen in {stability[str(result.order)]:.0%} of {result.order_evidence['stability']['draws']} " \
               "noise draws"
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
    from hopkinson.analysis.params import AnalysisParams

    values: dict[str, Any] = {"max_order": args.max_order, "order": args.order, "draws": args.draws,
                              "seed": args.seed, "uncertainty": not args.no_uncertainty}
    if args.sample_rate is not None:
        values["sample_rate_hz"] = args.sample_rate
    try:
        return AnalysisParams.from_options(**values)
    except AnalysisError as exc:
        raise named_by_flag(exc, FLAGS) from None


def named_by_flag(exc: AnalysisError, flags: dict[str, str]) -> AnalysisError:
    """The AnalysisParams check's error with each option named by the command's flag."""
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
    result, uncertainty, warnings = fitted.identification, fitted.uncertainty, clipped + fitted.warnings
    report = identification_report(result, str(args.record), uncertainty, warnings)
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
            sys.stdout.write(explain(report) + "\n")
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


def explain(report: dict[str, Any]) -> str:
    """The trail of what decided the identification (issue 17, `--explain`): where the noise was
    measured and its levels, motion left out of it, the band, V by order and the order test's
    comparisons, the model error, and what was claimed or not and why. Read from the report
    (the JSON), so it says what the stages recorded, not a second account of them."""
    from hopkinson.analysis.modes import RESONANCE_MAX_DAMPING, Mode, ModeKind, claimed
    from hopkinson.analysis.structure import Structure

    noise = report.get("noise") or {}
    pre = report.get("preprocessing") or {}
    lines = ["how this identification was decided:"]
    def rms(v: Any) -> str:
        return "not measured" if v is None else f"{v:.4g}"

    lines.append(f"  noise (RMS, channel units): reference {rms(noise.get('reference_rms'))} "
                 f"({noise.get('reference_source')}), response {rms(noise.get('response_rms'))} "
                 f"({noise.get('response_source')})")
    lead = noise.get("lead_in")
    if lead:
        to = ("to a quarter of the pulse's width before its foot: the window's margins left none" if lead["to_foot"]
              else "to the window's margin before the pulse")
        lines.append(f"  lead-in at rest: {lead['start_s'] * 1e3:.4g}–{lead['stop_s'] * 1e3:.4g} ms ({to})")
    elif "lead_in" in noise:
        lines.append("  lead-in at rest: none (the pulse starts too near the record's start)")
    # without a lead-in at rest the noise is measured on the motion all the same (with a warning)
    kept = "lead_in" in noise and not lead
    for m in noise.get("motion_after_pulse") or []:
        why = (f"moves coherently in both channels (power-weighted coherence {m['coherence']:.2f})"
               if m.get("coherence") is not None else m.get("reason") or "too short to judge by coherence")
        lines.append(f"  motion{'' if kept else ', not noise'}: {m['start_s'] * 1e3:.4g}–{m['stop_s'] * 1e3:.4g} ms "
                     f"{why}: " + ("measured as noise all the same, there being no lead-in at rest" if kept
                                   else "left out of the noise"))
    shift = pre.get("response_realigned_samples")
    if shift:
        lines.append(f"  realigned: the response delayed by {shift} samples before the fit (it led the reference by "
                     f"{pre.get('response_lead_by_cross_correlation_samples', 0.0):.3g} samples by their "
                     f"cross-correlation); the model's delay, {report.get('delay_samples', 0.0):.3g} samples, "
                     "carries the lead")
    band = report.get("supported_band_hz")
    if band:
        lines.append(f"  band: {band[0] / 1e3:.4g}–{band[1] / 1e3:.4g} kHz, where the reference's spectrum stands "
                     "20 dB above its noise and within 40 dB of its maximum; "
                     f"{pre.get('fitted_bins')} bins fitted over {pre.get('window_samples')} samples"
                     + (" (a transient term fitted: the record ends before the response settles)"
                        if pre.get("transient_term") else ""))
    evidence = report.get("order_evidence") or {}
    costs = evidence.get("cost_by_order") or {}
    if costs:
        lines.append("  V by order: " + ", ".join(f"{n}: {v:.4g}" for n, v in costs.items() if v is not None))
    for c in evidence.get("comparisons") or []:
        if c.get("beaten"):
            lines.append(f"  order {c['order']} beaten by {c['against']}: F {c['f']:.3g} > {c['f_critical']:.3g}, "
                         f"response change {c['response_change']:.2%}")
    lines.append(f"  order {report.get('order')} ({report.get('order_selection')}): "
                 f"{evidence.get('criterion', '')}")
    if evidence.get("structure") == Structure.ALL_POLE:
        why = evidence.get("structure_reason") or "chosen over the model with free zeros"
        lines.append(f"  structure: all-pole (no finite zeros, delay of either sign): {why}")
    error = noise.get("model_error") or {}
    if error.get("detected"):
        lo, hi = error.get("range_hz") or (None, None)
        lines.append(f"  model error: the residual is {error['residual_over_noise']:.3g}× the noise's, "
                     f"{error['rms_percent_of_peak']:.2g} % of the peak RMS, mostly "
                     f"{(lo or 0) / 1e3:.3g}–{(hi or 0) / 1e3:.3g} kHz, its power ∝ |U|^{2 * (error.get('drive_exponent') or 0.0):.2g} "
                     "(0: independent of the drive): weighed in a second fit and drawn in the uncertainty")
    else:
        lines.append(f"  model error: none beyond the noise (residual {error.get('residual_over_noise', 1.0):.3g}× "
                     "the noise's)")
    for m in map(Mode.from_dict, report.get("modes") or []):
        if m.kind != ModeKind.COMPLEX:
            continue
        f_n = (m.natural_frequency_hz or 0.0) / 1e3
        why = ("claimed (inside the band)" if claimed(m)
               else "not claimed: a pole–zero doublet" if m.cancelled
               else f"not claimed: damped more than ζ = {RESONANCE_MAX_DAMPING:g}, no resonance" if m.supported
               else "not claimed: beyond the band, placed by the rise it gives inside it" if m.shapes_band
               else "not claimed: outside the supported band")
        lines.append(f"  pole pair at {f_n:.4g} kHz, ζ {m.damping_ratio:.3g}: {why}")
    if report.get("resonance_above_hz"):
        lines.append(f"  resonance: > {report['resonance_above_hz'] / 1e3:.4g} kHz, in a null of the excitation")
    return "\n".join(lines)


def register(subparsers: Any) -> None:
    """Add the `identify` sub-command."""
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
    p.add_argument("--max-order", type=int, default=12, metavar="N", help="largest order tried (default 12)")
    p.add_argument("--order", type=int, metavar="n", help="fit exactly this order instead of choosing it")
    p.add_argument(
        "--sample-rate",
        type=float,
        metavar="HZ",
        # None: analysis.params.DEFAULT_ANALYSIS_RATE_HZ (resolved by AnalysisParams)
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
