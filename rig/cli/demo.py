"""`hopkinson demo`: a short campaign on an in-process simulated rig, with its report.

    hopkinson demo [--shots N] [--out DIR] [--sim-config PATH] [--report pdf,html | --no-report]

Starts the simulated rig (config/sim.toml: the three instruments on free loopback ports and a
pty), writes a demo plan of N shots (default 3) at rising reservoir pressures into DIR (default
demo-output/demo-plan.toml), runs it as a campaign into a new run folder DIR/demo-<UTC time>
(the plan authorises its own shots: simulation only), writes the report and prints where
everything is. In simulation every shot file holds the simulated sensor's truth (its "sensor"
block: drivers/sim/sensor_truth.py); the demo prints, per shot, each figure with its 95 %
interval beside that truth (the sensitivity: the mean of both directions, f_n, ζ, both FBSD
edges, the tension/compression asymmetry ε), "not determined" with the reason where the shot
does not determine a figure, and the shock sensitivity's verdict. How often these intervals hold
their truths over many demo campaigns is docs/coverage_realistic.py --demo's study.

Exit codes as `hopkinson campaign run`: 0 done; 2 bad input; 3 a shot aborted.
`make demo` runs `hopkinson demo --out demo-output`.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from hopkinson.analysis.key_figures import Figure
from hopkinson.rig.cli.campaign import ProgressPrinter, report_formats
from hopkinson.rig.cli.main import DEFAULT_SIM_CONFIG, DEFAULT_SIM_RIG_CONFIG
from hopkinson.rig.errors import ConfigError

DEFAULT_OUT = Path("demo-output")
MAX_SHOTS = 50
PRESSURE_RANGE_BAR = (1.5, 3.0)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `demo` sub-command."""
    p = subparsers.add_parser("demo", help="run a short campaign on the simulated rig and write its report",
                              description="Start the simulated rig in-process, fire a short campaign, write the "
                                          "shot files and the report, and print where they are.")
    p.add_argument("--shots", type=int, default=3, help=f"number of shots (1..{MAX_SHOTS}, default %(default)s)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default %(default)s)")
    p.add_argument("--sim-config", type=Path, default=DEFAULT_SIM_CONFIG,
                   help="simulator TOML (default %(default)s)")
    p.add_argument("--config", type=Path, default=DEFAULT_SIM_RIG_CONFIG,
                   help="rig TOML for limits, timeouts and analysis constants (default %(default)s)")
    p.add_argument("--report", default="pdf,html", metavar="FORMATS", help="report formats (default %(default)s)")
    p.add_argument("--no-report", action="store_true",
                   help="do not write the report (the figures beside their truths are printed all the same)")
    p.set_defaults(func=demo_command)


def demo_plan_text(shots: int) -> str:
    """A plan of `shots` shots at pressures rising evenly over PRESSURE_RANGE_BAR (projectile No. 3)."""
    lo, hi = PRESSURE_RANGE_BAR
    lines = [
        "# Written by `hopkinson demo`: a short campaign for the simulated rig.",
        'name = "demo"',
        'operator = "demo"',
        'description = "Simulated rig: the demo campaign."',
        "authorise_firing = true   # simulated rig only: the plan authorises its own shots",
        "",
        "[accelerometer]",
        'model = "SIM-ACC"',
        'serial = "SIM0001"',
        "",
        "[defaults]",
        "projectile = 3",
        "",
        "[defaults.analysis]",
        "max_order = 8",
        "sample_rate_hz = 1.0e6",
    ]
    for i in range(shots):
        p = lo if shots == 1 else lo + (hi - lo) * i / (shots - 1)
        lines += ["", "[[shots]]", f"pressure_bar = {p:.3f}"]
    return "\n".join(lines) + "\n"


FIGURE_ROWS = (  # (name, KeyFigures attribute or FBSD level, truth key, scale, unit, digits of the truth)
    ("sensitivity", "sensitivity", "dc_gain", 1.0, "× nominal", 4),
    ("f_n", "natural_frequency_hz", "natural_frequency_hz", 1e3, "kHz", 3),
    ("ζ", "damping_ratio", "damping_ratio", 1.0, "", 4),
    ("FBSD ±5 %", "5", "fbsd_5", 1e3, "kHz", 3),
    ("FBSD ±10 %", "10", "fbsd_10", 1e3, "kHz", 3),
)
UNDETERMINED_KEYS = {"sensitivity": "dc_gain", "5": "fbsd_5_hz", "10": "fbsd_10_hz"}


def truth_lines(label: str, kf: Any, results: dict[str, Any], truth: dict[str, Any] | None) -> list[str]:
    """The demo's lines for one shot: each figure with its 95 % interval beside the simulated truth
    (drivers/sim/sensor_truth), or "not determined" and why; the asymmetry ε; the shock
    sensitivity's verdict. The truth of the sensitivity is put in the analysis' units (the
    analysis divides by the amplifier gain and the nominal sensitivity it was given)."""
    sensor = (truth or {}).get("sensor") or {}
    params = results.get("params") or {}
    unit_scale = 1.0
    if truth and params.get("amp_gain") and params.get("sensitivity_v_per_m_s2"):
        unit_scale = (truth["amplifier_gain"] * truth["sensitivity_v_per_m_s2"]
                      / (params["amp_gain"] * params["sensitivity_v_per_m_s2"]))
    true = {"dc_gain": sensor.get("dc_gain", math.nan) * unit_scale,
            "natural_frequency_hz": sensor.get("natural_frequency_hz", math.nan),
            "damping_ratio": sensor.get("damping_ratio", math.nan),
            "fbsd_5": (sensor.get("fbsd_hz") or {}).get("5", math.nan),
            "fbsd_10": (sensor.get("fbsd_hz") or {}).get("10", math.nan)}
    head = f"  {label}:"
    if not kf.is_result:
        return [f"{head} {kf.not_a_result_reason}"]
    parts = []
    for name, attr, key, scale, unit, digits in FIGURE_ROWS:
        figure = kf.fbsd_hz.get(attr) if attr in ("5", "10") else getattr(kf, attr)
        why = kf.not_determined.get(UNDETERMINED_KEYS.get(attr, attr))
        truth_text = f"truth {true[key] / scale:.{digits}f}" if math.isfinite(true[key]) else "no truth"
        if figure is None or figure.value is None or why:
            parts.append(f"{name} not determined ({why or 'not claimed'}; {truth_text})")
        else:
            parts.append(f"{name} {interval_text(figure, scale, unit)} ({truth_text})")
    epsilon = ((results.get("uncertainty") or {}).get("input_terms") or {}).get("asymmetry")
    if epsilon and epsilon.get("value") is not None:
        parts.append(f"ε (tension ÷ compression − 1) {interval_text(Figure.of(epsilon), 1.0, '')} "
                     f"(truth {sensor.get('asymmetry_epsilon', math.nan):+.4f})")
    shock = kf.not_determined.get("shock_sensitivity")
    parts.append(f"S_sh {shock}" if shock else
                 f"S_sh {kf.shock_sensitivity.format()}" if kf.shock_sensitivity is not None else "S_sh —")
    return [head] + [f"    {p}" for p in parts]


def interval_text(figure: Figure, scale: float, unit: str) -> str:
    """'29.701 kHz [29.679, 29.724]': the value and its 95 % interval (as it is: an interval need
    not be symmetric), to the decimals two significant digits of U need; the value alone without."""
    suffix = f" {unit}" if unit else ""
    if figure.interval is None or figure.expanded is None:
        return f"{figure.format(scale)}{suffix}"
    decimals = max(0, 1 - math.floor(math.log10(figure.expanded / scale))) if figure.expanded > 0 else 4
    lo, hi = figure.interval
    return f"{figure.value / scale:.{decimals}f}{suffix} [{lo / scale:.{decimals}f}, {hi / scale:.{decimals}f}]"


def _shot_truth(path: Path) -> dict[str, Any] | None:
    """The simulated truth a shot file holds (None when it holds none)."""
    from hopkinson.rig.shotfile import read_shot_meta

    try:
        return read_shot_meta(path).simulated_truth
    except (OSError, ValueError, KeyError):
        return None


def demo_command(args: argparse.Namespace) -> int:
    from hopkinson.fileio import atomic_write
    from hopkinson.rig.campaign import CampaignRunner
    from hopkinson.rig.campaign_setup import prepare_run
    from hopkinson.rig.config import load_rig_config, load_sim_config
    from hopkinson.rig.events import EventBus
    from hopkinson.rig.instruments import open_instruments
    from hopkinson.rig.report_data import run_report, write_run_report
    from hopkinson.rig.sim_session import sim_session

    if not 1 <= args.shots <= MAX_SHOTS:
        raise ConfigError(f"--shots: must be 1..{MAX_SHOTS}, got {args.shots}")
    formats = [] if args.no_report else report_formats(args.report)
    config = load_rig_config(args.config)
    sim_config = load_sim_config(args.sim_config)
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        plan_path = atomic_write(args.out / "demo-plan.toml", demo_plan_text(args.shots))
    except OSError as exc:
        raise ConfigError(f"--out: cannot write into {args.out}: {exc.strerror or exc}") from None
    run, plan = prepare_run(plan_path, runs_dir=args.out)
    print(f"demo: simulated rig started; firing {args.shots} shot(s) into {run.path}", flush=True)

    bus = EventBus()
    printer = ProgressPrinter()
    bus.subscribe(printer)
    with sim_session(config, sim_config) as session:
        with open_instruments(session.config, session.simulated_truth) as instruments:
            runner = CampaignRunner(run, plan, instruments, session.config, bus)
            printer.runner = runner
            outcome = runner.run()
        fired = session.world.shots_fired

    print(f"demo: {outcome.message}; the simulated rig fired {fired} shot(s)", flush=True)
    report = run_report(run.path)
    for entry in report.shots:
        kf = entry.key_figures
        if kf is None:
            print(f"  {entry.label}: {entry.error or 'no analysis'}", flush=True)
            continue
        truth = _shot_truth(run.shots_dir / f"{entry.label}.h5")
        for line in truth_lines(entry.label, kf, entry.stored, truth):
            print(line, flush=True)
    if formats:
        for path in write_run_report(run.path, formats, report):
            print(f"report: {path}", flush=True)
    print(f"shot files: {run.shots_dir}", flush=True)
    if outcome.exit_code != 0:
        print(f"demo: {outcome.message}", flush=True)
    return outcome.exit_code
