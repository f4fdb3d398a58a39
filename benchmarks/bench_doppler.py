"""Benchmark: demodulation of a 10-million-sample PM beat (100 ms at 100 MS/s).

Baseline, measured in the same run: the textbook chain, scipy.signal.hilbert of the whole
record, numpy.unwrap of its angle and numpy.gradient, velocity = dφ/dt · d/(2π(φ − ξ)), box-car
averaged to the analysis rate for the accuracy comparison. Both are scored against the known
velocity of the simulated shot (100 000 g, 38.6 µs half-sine, SNR 30 dB, 2 µm grating).

Prints the figures and, on its last line, one JSON object.

    .venv/bin/python benchmarks/bench_doppler.py [--samples N] [--repeats R]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from scipy import signal

from hopkinson.analysis.doppler import demodulate
from hopkinson.drivers.sim.doppler_beat import DEFAULT_GRATING_PITCH_M, pm_beat
from hopkinson.drivers.sim.shock import G_M_S2, half_sine_m_s2, velocity_m_s

DT = 1e-8
PULSE_START_S = 1e-3
WIDTH_S = 38.6e-6
PEAK_G = 100_000


def baseline_velocity(x: np.ndarray, sample_interval_s: float, pitch_m: float) -> np.ndarray:
    """hilbert → unwrap(angle) → gradient: velocity at every raw sample (m/s)."""
    z = signal.hilbert(x - np.mean(x))
    phase = np.unwrap(np.angle(z))
    return np.gradient(phase, sample_interval_s) * pitch_m / (4.0 * np.pi)


def scores(velocity: np.ndarray, time_s: np.ndarray, true_t: np.ndarray, true_v: np.ndarray) -> dict[str, float]:
    """Max and RMS velocity error, relative to the peak velocity, away from the record's ends."""
    err = (velocity - np.interp(time_s, true_t, true_v))[200:-200]
    peak = float(true_v.max())
    return {"max_error_rel": float(np.max(np.abs(err)) / peak), "rms_error_rel": float(np.sqrt(np.mean(err**2)) / peak)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    n = args.samples
    t = np.arange(n) * DT
    acc = half_sine_m_s2(t, WIDTH_S, PEAK_G * G_M_S2, PULSE_START_S)
    vel = velocity_m_s(acc, DT)
    beat = pm_beat(vel, DT, snr_db=30.0, initial_phase_rad=1.0, rng=np.random.default_rng(0)).astype(np.float32)
    print(f"record: {n} samples at {1 / DT / 1e6:g} MS/s ({n * DT * 1e3:g} ms), peak velocity {vel.max():.2f} m/s")

    ours_s = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        d = demodulate(beat, DT, DEFAULT_GRATING_PITCH_M)
        ours_s.append(time.perf_counter() - t0)
    ours = min(ours_s)
    ours_acc = scores(d.velocity_m_s, d.time_s, t, vel)

    t0 = time.perf_counter()
    v_base = baseline_velocity(beat.astype(np.float64), DT, DEFAULT_GRATING_PITCH_M)
    base = time.perf_counter() - t0
    m = int(round(d.sample_interval_s / DT))
    blocks = n // m
    v_base_rate = v_base[: blocks * m].reshape(blocks, m).mean(axis=1)
    t_base_rate = (np.arange(blocks) * m + 0.5 * (m - 1)) * DT
    base_acc = scores(v_base_rate, t_base_rate, t, vel)

    print(f"analysis.doppler.demodulate : {ours:.3f} s (best of {args.repeats}) = {n / ours / 1e6:.1f} M samples/s; "
          f"velocity error max {ours_acc['max_error_rel']:.3%}, rms {ours_acc['rms_error_rel']:.4%} of peak")
    print(f"baseline hilbert+gradient   : {base:.3f} s = {n / base / 1e6:.1f} M samples/s; "
          f"velocity error max {base_acc['max_error_rel']:.3%}, rms {base_acc['rms_error_rel']:.4%} of peak "
          f"(box-car to {1 / d.sample_interval_s / 1e6:g} MS/s)")
    print(f"speed-up: {base / ours:.2f}x")
    print(json.dumps({
        "benchmark": "doppler_demodulation",
        "samples": n,
        "seconds": ours,
        "samples_per_second": n / ours,
        "baseline_seconds": base,
        "baseline_samples_per_second": n / base,
        "speedup": base / ours,
        "velocity_max_error_rel": ours_acc["max_error_rel"],
        "velocity_rms_error_rel": ours_acc["rms_error_rel"],
        "baseline_velocity_max_error_rel": base_acc["max_error_rel"],
        "baseline_velocity_rms_error_rel": base_acc["rms_error_rel"],
        "bandwidth_hz": d.bandwidth_hz,
    }))


if __name__ == "__main__":
    main()
