"""`hopkinson report`: the calibration report of a shot file or of a campaign run folder.

    hopkinson report (SHOT.h5 | RUN_FOLDER) [-o report.pdf] [-o report.html] [--json]

The format follows each -o suffix (.pdf or .html; -o may be given more than once). Without -o:
a shot file gets <shot>.pdf beside it, a run folder <run>/report/report.pdf. A shot's report:
identity of the accelerometer and the rig, the excitation (pulse, spectrum), the loss by order
with the chosen order, the model's magnitude and phase with the ±5 %/±10 % bands and the FBSD,
the pole analysis, the DCM with its compensated response and step response, the shock
sensitivity. A run folder's report adds, across its shots, the spread (mean, standard
deviation), the combined key figures (mean, repeatability, U) and the cross-validation matrix.
--json prints {"reports": [...], "shots": [{"id", "state", "analysed", "error", "key_figures"}],
"campaign": statistics or null, "unreadable": [{"id", "path", "reason"}]} (a damaged or
unreadable shot file of a run folder: every file is checked against its checksums first, and a
damaged single shot file is refused, exit 2); key_figures is analysis.key_figures.KeyFigures.to_dict() (each
uncertain figure as {"value", "u", "interval"}). A shot whose analysis failed is reported with
its error.
Exit codes: 0 written; 2 bad input (no such file, not a shot file or run folder, a run folder
without shot files, an unknown -o suffix or a missing output folder).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hopkinson.rig.cli.main import emit_json
from hopkinson.rig.errors import ConfigError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `report` sub-command."""
    p = subparsers.add_parser("report", help="calibration report (PDF/HTML) of a shot file or a campaign run folder",
                              description="Write the calibration report of a shot file or of a campaign run folder.")
    p.add_argument("source", type=Path, metavar="SHOT.h5|RUN_FOLDER", help="a shot file or a campaign run folder")
    p.add_argument("-o", "--output", type=Path, action="append", default=[], metavar="PATH",
                   help="report file, .pdf or .html (repeatable; default: beside the shot / in the run's report/)")
    p.add_argument("--json", action="store_true", help="one JSON object: files written, shots, campaign statistics")
    p.set_defaults(func=report_command)


def default_outputs(source: Path) -> list[Path]:
    """<shot>.pdf beside a shot file; <run>/report/report.pdf for a run folder."""
    if source.is_dir():
        return [source / "report" / "report.pdf"]
    return [source.with_suffix(".pdf")]


def report_command(args: argparse.Namespace) -> int:
    from hopkinson.reports.statistics import campaign_statistics
    from hopkinson.reports.writers import write_report
    from hopkinson.rig.report_data import report_for

    outputs = args.output or default_outputs(args.source)
    for out in outputs:
        if out.suffix.lower() not in (".pdf", ".html"):
            raise ConfigError(f"-o {out}: a report is .pdf or .html")
        if not out.parent.is_dir():
            if args.source.is_dir() and out.parent == args.source / "report":
                out.parent.mkdir()
            else:
                raise ConfigError(f"-o {out}: folder {out.parent} does not exist")
    report = report_for(args.source)
    stats = campaign_statistics(report.shots, report.sine_calibration) if report.campaign else None
    written = write_report(report, outputs, inputs=[args.source], stats=stats)
    if args.json:
        emit_json({
            "reports": [str(p) for p in written],
            "shots": [{"id": e.label, "state": e.state, "analysed": e.analysis is not None, "error": e.error,
                       "key_figures": e.key_figures.to_dict() if e.key_figures is not None else None}
                      for e in report.shots],
            "campaign": stats.to_dict() if stats is not None else None,
            "unreadable": report.unreadable,
        })
    else:
        for path in written:
            print(f"report: {path}")
    return 0
