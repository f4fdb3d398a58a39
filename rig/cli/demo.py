"""`hopkinson demo`: a short campaign on an in-process simulated rig, with its report.

    hopkinson demo [--shots N] [--out DIR] [--sim-config PATH] [--report pdf,html]

Starts the simulated rig (config/sim.toml: the three instruments on free loopback ports and a
pty), writes a demo plan of N shots (default 3) at rising reservoir pressures into DIR (default
demo-output/demo-plan.toml), runs it as a campaign into a new run folder DIR/demo-<UTC time>
(the plan authorises its own shots: simulation only), writes the report and prints where
everything is. In simulation every shot file holds the true accelerometer model; the demo
prints, per shot, the identified main resonance beside the truth and the error of its pole.

Exit codes as `hopkinson campaign run`: 0 done; 2 bad input; 3 a shot aborted.
`make demo` runs `hopkinson demo --out demo-output`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

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


def demo_command(args: argparse.Namespace) -> int:
    from hopkinson.reports.data import truth_comparison
    from hopkinson.rig.campaign import CampaignRunner
    from hopkinson.rig.campaign_setup import prepare_run
    from hopkinson.rig.config import load_rig_config, load_sim_config
    from hopkinson.rig.events import EventBus
    from hopkinson.rig.instruments import open_instruments
    from hopkinson.rig.report_data import run_report, write_run_report
    from hopkinson.rig.sim_session import sim_session

    from hopkinson.fileio import atomic_write

    if not 1 <= args.shots <= MAX_SHOTS:
        raise ConfigError(f"--shots: must be 1..{MAX_SHOTS}, got {args.shots}")
    formats = report_formats(args.report)
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
        cmp = truth_comparison(entry)
        kf = entry.key_figures
        if cmp is None and kf is not None:  # analysed, but no resonance the shot supports
            band = kf.supported_band_hz
            where = f" (supported band up to {band[1] / 1e3:.1f} kHz)" if band else ""
            print(f"  {entry.label}: f_n not claimed: the resonance lies beyond what the pulse excites{where}; "
                  f"FBSD ±5 % {kf.fbsd_hz['5'].format(1e3, unit='kHz')}", flush=True)
            continue
        if cmp is None:
            print(f"  {entry.label}: {entry.error or 'no analysis'}", flush=True)
            continue
        f_n = entry.key_figures.natural_frequency_hz  # value ± U when the shot carries its uncertainty
        f_n_text = f_n.format(1e3, unit="kHz") if f_n.expanded is not None else f"{f_n.value / 1e3:.3f} kHz"
        print(f"  {entry.label}: f_n {f_n_text} (truth "
              f"{cmp['truth_natural_frequency_hz'] / 1e3:.3f}), zeta {cmp['damping_ratio']:.4f} (truth "
              f"{cmp['truth_damping_ratio']:.4f}), pole error {cmp['pole_error_percent']:.3f} %", flush=True)
    for path in write_run_report(run.path, formats, report):
        print(f"report: {path}", flush=True)
    print(f"shot files: {run.shots_dir}", flush=True)
    if outcome.exit_code != 0:
        print(f"demo: {outcome.message}", flush=True)
    return outcome.exit_code
