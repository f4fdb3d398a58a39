"""`hopkinson plan-shot`: which projectile and pressure give a target peak, predicted from the
rig's physics (analysis.bar: launcher, impact, dispersion, separation) before anything is fired.

    hopkinson plan-shot (--peak-g G | --peak-m-s2 A) [--sensor-fn-hz F] [--config rig.toml] [--json]

For each projectile of the rig's `[bar]` (the paper's three by default): the pressure needed,
the pulse (equivalent half-sine width δ, the width above 10 %), the peak, the spectrum's −3 dB
frequency and supported band, and with --sensor-fn-hz whether δ ≤ 1.06/f_n (the paper's Eq. 36)
holds; then which projectile to load and why. A target no projectile reaches within the rig's
`[limits]` is refused with the reason, exit 2. Pure computation: it only reads the configuration
(never an instrument).
"""

from __future__ import annotations

import argparse
from typing import Any

from hopkinson.rig.cli.main import emit_json


def register(subparsers: Any) -> None:
    """Add the `plan-shot` sub-command."""
    from hopkinson.rig.config_paths import default_rig_config

    p = subparsers.add_parser(
        "plan-shot", help="which projectile and pressure give a target peak (bar model; fires nothing)",
        description="Predict, for each projectile of the rig, the pressure for a target peak acceleration, the "
                    "pulse width, its spectrum's -3 dB and supported band, and whether the pulse excites a sensor "
                    "(delta <= 1.06/f_n); say which projectile to load. Reads the rig configuration's [bar] and "
                    "[limits] only.")
    level = p.add_mutually_exclusive_group(required=True)
    level.add_argument("--peak-g", type=float, metavar="G", help="target peak acceleration in g (9.80665 m/s²)")
    level.add_argument("--peak-m-s2", type=float, metavar="A", help="target peak acceleration in m/s²")
    p.add_argument("--sensor-fn-hz", type=float, metavar="F", help="the sensor's natural frequency (Hz)")
    p.add_argument("--config", default=None, metavar="RIG.toml",
                   help=f"rig configuration whose [bar] and [limits] are used (default {default_rig_config()}; "
                        "only read)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_plan_shot)


def run_plan_shot(args: argparse.Namespace) -> int:
    from hopkinson.analysis.bar import G_M_S2, plan_shot
    from hopkinson.rig.config import load_rig_config
    from hopkinson.rig.config_paths import default_rig_config
    from hopkinson.rig.errors import ConfigError

    target = args.peak_m_s2 if args.peak_m_s2 is not None else args.peak_g * G_M_S2
    if not target > 0:
        raise ConfigError(f"the target peak must be positive, got {target:g} m/s²")
    if args.sensor_fn_hz is not None and not args.sensor_fn_hz > 0:
        raise ConfigError(f"--sensor-fn-hz must be positive, got {args.sensor_fn_hz:g}")
    config = load_rig_config(args.config or default_rig_config())
    try:
        plan = plan_shot(config.bar.rig(), target, sensor_fn_hz=args.sensor_fn_hz,
                         min_pressure_bar=config.limits.min_pressure_bar, max_pressure_bar=config.limits.max_pressure_bar)
    except ValueError as exc:
        raise ConfigError(f"{config.path}: [bar]: {exc}") from None
    if args.json:
        emit_json(plan.to_dict())
    else:
        print(plan_text(plan))
    if plan.chosen is None:
        raise ConfigError(f"{config.path}: {target / G_M_S2:,.0f} g: {plan.reason}")
    return 0


def plan_text(plan: Any) -> str:
    """The plan as a table and a sentence."""
    from hopkinson.analysis.bar import G_M_S2, PAPER_RULE

    head = f"target {plan.target_peak_m_s2 / G_M_S2:,.0f} g ({plan.target_peak_m_s2:.4g} m/s²)"
    if plan.sensor_fn_hz:
        head += f", sensor f_n {plan.sensor_fn_hz / 1e3:.3g} kHz (needs δ ≤ {PAPER_RULE / plan.sensor_fn_hz * 1e6:.1f} µs)"
    lines = [head, f"{'No.':>4} {'pressure':>10} {'speed':>9} {'δ':>8} {'>10 %':>8} {'-3 dB':>9} {'band':>9}  excites"]
    for o in plan.options:
        rule = "—" if o.paper_rule_holds is None else ("yes" if o.paper_rule_holds else "no")
        row = (f"{o.projectile:>4} {o.pressure_bar:>7.3g} bar {o.speed_m_s:>5.1f} m/s {o.width_s * 1e6:>5.1f} µs "
               f"{o.width_10_s * 1e6:>5.1f} µs {o.minus_3db_hz / 1e3:>5.1f} kHz {o.supported_band_hz / 1e3:>5.0f} kHz"
               f"  {rule}")
        if not o.reachable:
            row += f"  (out of reach: {o.why_not})"
        lines.append(row)
    lines.append(f"load projectile No. {plan.chosen}: {plan.reason}" if plan.chosen is not None else
                 f"no projectile: {plan.reason}")
    return "\n".join(lines)
