"""`hopkinson compare-sine`: a shock-identified model against a sinusoidal calibration.

    hopkinson compare-sine MODEL.json SINE.csv [--dcm DCM.json] [--reference-hz F]
                           [--plot OUT.png] [--json]

MODEL.json: a model file (`hopkinson identify -o`, or a file with the model under "model").
SINE.csv: columns frequency_hz,magnitude,phase_deg (optional u_magnitude_rel,u_phase_deg).
The compensated magnitude is sine × DCM: the DCM of --dcm, else the one MODEL.json carries,
else the default automatic DCM designed from the model (analysis.dcm_design).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from hopkinson.analysis.errors import AnalysisError
from hopkinson.fileio import UnsafeOutputError, check_output_path
from hopkinson.rig.cli.main import emit_json


def run_compare_sine(args: argparse.Namespace) -> int:
    """Compare, print a table (or --json), optionally draw the plot."""
    from hopkinson.analysis.dcm import DCM, load_dcm
    from hopkinson.analysis.dcm_design import ShotSupport, design_compensation
    from hopkinson.analysis.model import DiscreteModel, load_json_object
    from hopkinson.analysis.sine_comparison import (
        band_consistency,
        compare_sine,
        read_sine_calibration,
    )

    plot = None
    if args.plot:
        try:
            plot = check_output_path(args.plot, [args.model, args.sine] + ([args.dcm] if args.dcm else []))
        except UnsafeOutputError as exc:
            raise AnalysisError(str(exc)) from None
    data = load_json_object(args.model, "model")
    model = DiscreteModel.from_dict(data.get("model", data), source=str(args.model))
    sine = read_sine_calibration(args.sine)
    if args.dcm:
        dcm, dcm_source = load_dcm(args.dcm), str(args.dcm)
    elif isinstance(data.get("dcm"), dict):
        dcm, dcm_source = DCM.from_dict(data["dcm"], source=f"{args.model} (dcm)"), f"{args.model} (its DCM)"
    else:
        ident = data.get("identification", data)
        support = ShotSupport.from_dict(ident if isinstance(ident, dict) else {}, model)
        dcm, dcm_source = design_compensation(support).dcm, "the default DCM designed from the model"
    comparison = compare_sine(model, sine, dcm, args.reference_hz)
    result: dict[str, Any] = {"model": str(args.model), "sine": str(args.sine), "dcm": dcm_source,
                              **comparison.to_dict()}
    band = (data.get("uncertainty") or {}).get("response_band")
    consistency = band_consistency(comparison, band) if isinstance(band, dict) else None
    result["response_band"] = consistency
    if plot is not None:
        from hopkinson.reports.sine_plot import write_sine_plot

        write_sine_plot(comparison, plot)
        result["plot"] = str(plot)
    if args.json:
        emit_json(result)
        return 0
    out = sys.stdout
    out.write(f"{args.model} against the sine calibration {args.sine} (normalised at "
              f"{comparison.reference_frequency_hz:g} Hz; compensated: {dcm_source})\n")
    header = f"  {'f (kHz)':>9} {'sine':>8} {'model':>8} {'error %':>8} {'±2u %':>7} {'phase err °':>11} {'sine×DCM':>9}\n"
    out.write(header)
    for i, f in enumerate(comparison.frequency_hz):
        u = "" if comparison.u_magnitude_rel is None else f"{200 * comparison.u_magnitude_rel[i]:.2f}"
        comp = "" if comparison.compensated_magnitude is None else f"{comparison.compensated_magnitude[i]:.4f}"
        flag = "" if comparison.consistent is None or comparison.consistent[i] else "  outside 2u"
        out.write(f"  {f / 1e3:>9.4g} {comparison.sine_magnitude[i]:>8.4f} {comparison.model_magnitude[i]:>8.4f} "
                  f"{comparison.magnitude_error_pct[i]:>+8.2f} {u:>7} {comparison.phase_error_deg[i]:>+11.2f} "
                  f"{comp:>9}{flag}\n")
    out.write(f"largest magnitude error {comparison.max_magnitude_error_pct:.2f} %; the phase error (the whole "
              f"model's, its fitted delay τ = {comparison.fitted_delay_s * 1e6:.3g} µs included) is that of a delay "
              f"of {comparison.phase_delay_s * 1e6:.3g} µs, the shock record's channel skew; model ÷ sine "
              f"sensitivity at the reference "
              f"frequency {comparison.sensitivity_ratio:.6g} (same units assumed)\n")
    if consistency is not None and consistency["max_e_n"] is not None:
        verdict = "consistent" if consistency["consistent"] else "NOT consistent"
        out.write(f"the sine points against the model's 95 % response band: largest E_n "
                  f"{consistency['max_e_n']:.2f} ({verdict}: E_n ≤ 1 at every point)\n")
    elif consistency is None:
        out.write("the model file carries no response band (identify with its uncertainty): no E_n\n")
    if comparison.compensated_fbsd_hz:
        parts = [f"±{k} %: " + ("beyond the last point" if v is None else f"{v / 1e3:.4g} kHz")
                 for k, v in comparison.compensated_fbsd_hz.items()]
        out.write("sine × DCM band: " + ", ".join(parts) + "\n")
    if plot is not None:
        out.write(f"wrote {plot}\n")
    return 0


def register(subparsers: Any) -> None:
    """Add the `compare-sine` sub-command."""
    p = subparsers.add_parser(
        "compare-sine",
        help="compare a shock model (and its DCM) with a sinusoidal calibration of the same sensor",
        description="Magnitude and phase error of the model at each frequency of a sine calibration "
        "(ISO 16063-11/-21), magnitudes normalised at a reference frequency, and the compensated magnitude "
        "sine x DCM. SINE.csv columns: frequency_hz,magnitude,phase_deg (optional u_magnitude_rel,u_phase_deg).",
    )
    p.add_argument("model", metavar="MODEL.json", help="model file from `hopkinson identify -o`")
    p.add_argument("sine", metavar="SINE.csv", help="the sine calibration points")
    p.add_argument("--dcm", metavar="DCM.json", help="DCM file (default: the model file's, else the automatic one)")
    p.add_argument("--reference-hz", type=float, metavar="F",
                   help="frequency the magnitudes are normalised at (default: the lowest sine point)")
    p.add_argument("--plot", metavar="OUT.png", help="draw the comparison (PNG)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_compare_sine)
