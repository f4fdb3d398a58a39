"""Benchmark: the uncertainty of one shot (analysis.uncertainty, GUM-S1 Monte Carlo).

Data: a simulated shot as the simulated rig records it (config/rig-sim.toml: 2 ms at 100 MS/s,
10 % pre-trigger; a 27 kHz / ζ 0.05 sensor behind a 200 kHz amplifier low-pass, projectile
No. 3's 38.6 µs half-sine of 50 000 g, 30 dB PM beat, 50 dB response noise).

Figures, all measured in the same run (best of --repeats):
1. one identification of the reduced record (analysis.identify) — the unit of the ratios;
2. the uncertainty alone at the default draws: draws per second, and its time as a ratio to
   one identification;
3. the whole per-shot analysis with its uncertainty (analysis.shot_analysis.analyse_raw_shot:
   reduction of the raw channels, identification, uncertainty, DCM design and check with the
   compensated peak's interval) — the time from capture to the result on screen, less the
   storing — as seconds and as a ratio to one identification. Aim: about 3 s on a 2-core
   machine;
4. the joint fit with a sine calibration (analysis.sine_joint; 40 points 0.5–20 kHz drawn
   from the truth with 0.3 % / 0.3°): one joint identification (three fits: the shock's, then
   two re-weighted joint ones) and its uncertainty, the whole as a ratio to one joint
   identification and to one plain identification (issue 17: under 10×).

    .venv/bin/python benchmarks/bench_uncertainty.py [--draws N] [--repeats 3]

Prints the figures and, on its last line, one JSON object.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np
from bench_identify import best_time  # the same timing rule (best of N)

from hopkinson.analysis.identify import identify, identify_with_sine
from hopkinson.analysis.options import DEFAULT_DRAWS, AnalysisOptions
from hopkinson.analysis.reduce import reduce_raw
from hopkinson.analysis.shot_analysis import analyse_raw_shot
from hopkinson.analysis.sine_comparison import SineCalibration
from hopkinson.analysis.uncertainty import evaluate
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.doppler_beat import raw_shot
from hopkinson.drivers.sim.shock import G_M_S2, half_sine_m_s2

DT = 1e-8
SAMPLES = 200_000
PRE_TRIGGER = 20_000
GAIN, SENSITIVITY = 10.0, 2e-7


TRUTH = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),), lowpass_hz=200_000.0)


def simulated_sine(seed: int = 1) -> SineCalibration:
    """A sine calibration of the truth (V per m/s² at the amplifier output), 0.3 % / 0.3°."""
    rng = np.random.default_rng(seed)
    f = np.arange(500.0, 20_001.0, 500.0)
    h = TRUTH.frequency_response(f) * GAIN * SENSITIVITY
    return SineCalibration(f, np.abs(h) * (1 + 0.003 * rng.standard_normal(f.size)),
                           np.degrees(np.angle(h)) + 0.3 * rng.standard_normal(f.size),
                           np.full(f.size, 0.003), np.full(f.size, 0.3), "simulated sine")


def simulated_shot(seed: int = 1) -> Any:
    t = np.arange(SAMPLES) * DT
    truth = TRUTH
    acc = half_sine_m_s2(t, 38.6e-6, 50_000 * G_M_S2, PRE_TRIGGER * DT)
    return raw_shot(acc, truth, DT, amp_gain=GAIN, sensitivity_v_per_m_s2=SENSITIVITY,
                    rng=np.random.default_rng(seed))


def run(draws: int, repeats: int) -> dict[str, Any]:
    raw = simulated_shot()
    record = reduce_raw(raw.doppler_v, raw.response_v, DT, amp_gain=GAIN, sensitivity_v_per_m_s2=SENSITIVITY).record
    ident_s, ident = best_time(lambda: identify(record), repeats)
    options = AnalysisOptions(draws=draws, seed=1)
    unc_s, result = best_time(lambda: evaluate(ident, options), repeats)
    params = AnalysisOptions(amp_gain=GAIN, sensitivity_v_per_m_s2=SENSITIVITY, draws=draws, seed=1)
    shot_s, shot = best_time(lambda: analyse_raw_shot(raw.doppler_v, raw.response_v, DT, params), repeats)
    no_unc = AnalysisOptions(amp_gain=GAIN, sensitivity_v_per_m_s2=SENSITIVITY, uncertainty=False)
    plain_s, _ = best_time(lambda: analyse_raw_shot(raw.doppler_v, raw.response_v, DT, no_unc), repeats)
    sine = simulated_sine()
    joint_s, joint = best_time(lambda: identify_with_sine(record, sine), repeats)
    joint_unc_s, joint_result = best_time(lambda: evaluate(joint, options), repeats)
    out = {
        "benchmark": "uncertainty",
        "draws": result.draws,
        "identification_s": ident_s,
        "uncertainty_s": unc_s,
        "draws_per_s": result.draws / unc_s,
        "uncertainty_ratio_to_identification": unc_s / ident_s,
        "shot_analysis_with_uncertainty_s": shot_s,
        "shot_analysis_ratio_to_identification": shot_s / ident_s,
        "shot_analysis_without_uncertainty_s": plain_s,
        "joint_identification_s": joint_s,
        "joint_uncertainty_s": joint_unc_s,
        "joint_whole_ratio_to_joint_identification": (joint_s + joint_unc_s) / joint_s,
        "joint_whole_ratio_to_identification": (joint_s + joint_unc_s) / ident_s,
        "joint_verdict_consistent": bool(joint.sine_joint.consistent),
        "order": ident.order,
        "natural_frequency_hz": shot.to_dict()["uncertainty"]["main_mode"]["natural_frequency_hz"],
    }
    print(f"one identification: {ident_s:.3f} s (order {ident.order})")
    print(f"uncertainty, {result.draws} draws: {unc_s:.3f} s = {out['draws_per_s']:.0f} draws/s "
          f"({out['uncertainty_ratio_to_identification']:.1f}× one identification)")
    print(f"whole shot analysis with uncertainty: {shot_s:.2f} s "
          f"({out['shot_analysis_ratio_to_identification']:.1f}× one identification; without it {plain_s:.2f} s)")
    print(f"joint fit with a sine calibration: {joint_s:.3f} s, its uncertainty ({joint_result.draws} draws) "
          f"{joint_unc_s:.3f} s; the whole {out['joint_whole_ratio_to_joint_identification']:.1f}× one joint "
          f"identification, {out['joint_whole_ratio_to_identification']:.1f}× one plain identification")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=DEFAULT_DRAWS)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(json.dumps(run(args.draws, args.repeats), allow_nan=False))


if __name__ == "__main__":
    main()
