"""The DCM on the simulated rig's realistic records (issue 40 item 6): for engineers judging the
automatic compensation.

    .venv/bin/python docs/dcm_realistic.py [--shots 24] [--projectiles 3] [--world realistic|clean]
                                           [--draws 100]

Each shot is one shot of config/sim.toml's world as shipped (the bar model's bipolar pulse, the
sensor bonded to the bar's end, a quadrature interferometer and every realistic effect; `clean`:
the same bar pulse with the effects off), shot number n at a pressure drawn from 1–4 bar (seed
2026), projectiles taken in turn from --projectiles, captured at 100 MS/s (2 ms) and analysed
exactly as a rig's shot is (analysis.shot_analysis.analyse_raw_shot, default options). Per shot:
the check's compensated peak error and RMS error (of the reference's peak), the verdict, the
widening reached, the noise gain, and whether the compensated peak's 95 % interval holds the
reference's peak. The summary: median and range of the compensated peak error, DCMs recommended
outside ±5 %, intervals holding the reference peak. The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def world_of(kind: str):  # noqa: ANN201 (drivers' WorldParams)
    from hopkinson.rig.config import load_sim_config

    world = load_sim_config(REPO / "config" / "sim.toml").world
    if kind == "clean":
        r = world.realism
        world = dataclasses.replace(world, realism=dataclasses.replace(
            r, bar_ringing=dataclasses.replace(r.bar_ringing, enabled=False),
            mount=dataclasses.replace(r.mount, enabled=False),
            transverse=dataclasses.replace(r.transverse, enabled=False),
            reference=dataclasses.replace(r.reference, noise=False, lowpass=False, delay=False, onset_errors=False)))
    return world


def study(shots: int, projectiles: list[int], kind: str, draws: int) -> list[dict]:
    from hopkinson.analysis.options import AnalysisOptions
    from hopkinson.analysis.shot_analysis import analyse_raw_shot
    from hopkinson.drivers.sim.world import CaptureSettings, simulate_shot

    world = world_of(kind)
    rng = np.random.default_rng(2026)
    rows = []
    for n in range(1, shots + 1):
        pressure = float(rng.uniform(1.0, 4.0))
        projectile = projectiles[(n - 1) % len(projectiles)]
        channels, truth = simulate_shot(world, pressure, projectile, CaptureSettings(100e6, 200_000, 20_000),
                                        shot_number=n)
        result = analyse_raw_shot(channels[1], channels[2], 1e-8, AnalysisOptions(
            amp_gain=truth["amplifier_gain"], sensitivity_v_per_m_s2=truth["sensitivity_v_per_m_s2"],
            max_order=6, draws=draws, seed=n), quadrature_v=channels.get(3)).to_dict()["dcm"]
        check, peak = result.get("check"), result.get("compensated_peak")
        holds = None
        if check and peak:
            holds = peak["interval"][0] <= check["reference_peak_m_s2"] <= peak["interval"][1]
        rows.append({"shot": n, "projectile": projectile, "pressure_bar": pressure,
                     "peak_error_pct": None if not check else check["peak_error_pct"]["compensated"],
                     "rms_error_pct": None if not check else check["rms_error_pct"]["compensated"],
                     "recommended": result.get("recommended"), "reached_widening": result.get("reached_widening"),
                     "noise_gain": result.get("noise_gain"), "interval_holds_reference": holds})
        r = rows[-1]
        print(f"shot {n:3d}  No. {projectile}  {pressure:4.2f} bar  peak {r['peak_error_pct']:+7.2f} %  "
              f"RMS {r['rms_error_pct']:5.2f} %  ×{r['reached_widening']:5.2f}  noise gain {r['noise_gain']:5.2f}  "
              f"{'recommended' if r['recommended'] else 'not recommended'}  interval holds: {holds}", flush=True)
    return rows


def summary(rows: list[dict]) -> dict:
    errors = np.array([r["peak_error_pct"] for r in rows if r["peak_error_pct"] is not None])
    bad = [r["shot"] for r in rows if r["recommended"] and abs(r["peak_error_pct"]) > 5.0]
    held = [r["interval_holds_reference"] for r in rows if r["interval_holds_reference"] is not None]
    return {"shots": len(rows), "median_peak_error_pct": float(np.median(errors)),
            "range_peak_error_pct": [float(errors.min()), float(errors.max())],
            "median_rms_error_pct": float(np.median([r["rms_error_pct"] for r in rows])),
            "recommended": sum(bool(r["recommended"]) for r in rows), "recommended_outside_5_pct": bad,
            "intervals_holding_reference": f"{sum(held)} of {len(held)}"}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--shots", type=int, default=24)
    p.add_argument("--projectiles", default="3", help="comma-separated, taken in turn (default: 3, as shipped)")
    p.add_argument("--world", choices=("realistic", "clean"), default="realistic")
    p.add_argument("--draws", type=int, default=100)
    args = p.parse_args(argv)
    rows = study(args.shots, [int(x) for x in args.projectiles.split(",")], args.world, args.draws)
    s = summary(rows)
    print(f"median compensated peak error {s['median_peak_error_pct']:+.2f} % (range "
          f"{s['range_peak_error_pct'][0]:+.1f} … {s['range_peak_error_pct'][1]:+.1f} %), median RMS "
          f"{s['median_rms_error_pct']:.2f} %; recommended {s['recommended']} of {s['shots']}, outside ±5 %: "
          f"{s['recommended_outside_5_pct'] or 'none'}; intervals holding the reference peak: "
          f"{s['intervals_holding_reference']}")
    print(json.dumps({"world": args.world, "projectiles": args.projectiles, **s, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
