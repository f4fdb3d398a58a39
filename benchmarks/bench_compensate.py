"""Streaming DCM compensation throughput against scipy.signal.lfilter on the whole record.

One record (default 10 000 000 samples of a noisy shock response at 1 MS/s) is compensated with
a shot's DCM (the automatic design for a 27 kHz, ζ = 0.05 sensor: order 2, then its band limit,
a linear-phase FIR)
four ways in the same run:
    lfilter whole    scipy.signal.lfilter(b, a, x) on the whole record (the baseline; b holds the
                     FIR stage's taps too)
    apply whole      analysis.dcm_stream.apply: second-order sections, then the FIR stage, one call
    stream           analysis.dcm_stream.DcmStream, blocks of --block samples with carried state (what
                     `hopkinson compensate` does), latency kept (--causal)
    stream aligned   the same with the latency removed (fractional-delay FIR, held-back tail)
The stream's output equals the whole-record filter (checked). Figures are samples per second
(best of the repeats) and ratios to the baseline. Then the design itself, timed (best of the
repeats): the automatic ratio sized to a 38.6 µs half-sine pulse (analysis.dcm_ratio, what every
shot analysis does) against the former fixed ×3 widening. The last line of output is one JSON
object.

Usage: .venv/bin/python benchmarks/bench_compensate.py [--samples N] [--block B] [--repeats R]
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import numpy as np
from scipy import signal

from hopkinson.analysis.dcm_design import ShotSupport, design_compensation
from hopkinson.analysis.dcm_stream import DcmStream, apply
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode


def best_rate(run: Callable[[], np.ndarray], samples: int, repeats: int) -> tuple[float, np.ndarray]:
    best, out = float("inf"), np.zeros(0)
    for _ in range(repeats):
        start = time.perf_counter()
        out = run()
        best = min(best, time.perf_counter() - start)
    return samples / best, out


def design_times(model: DiscreteModel, repeats: int) -> dict[str, float]:
    """Seconds (best of `repeats`) to design the shot's DCM: sized to a 38.6 µs half-sine pulse
    through the model, and for a fixed ×3 widening."""
    from hopkinson.analysis.dcm_ratio import ShotPulse
    from hopkinson.analysis.records import Record
    from hopkinson.analysis.response import model_output

    t = np.arange(4000) * model.sample_interval_s - 1e-3
    u = np.where((t >= 0) & (t <= 38.6e-6), np.sin(np.pi * t / 38.6e-6), 0.0)
    pulse = ShotPulse.of(Record(model.sample_interval_s, u, model_output(model, u)))
    support = ShotSupport(model, supported_band_hz=(0.0, 38_000.0), pulse=pulse)
    out = {}
    for name, options in (("pulse", AnalysisOptions()), ("widening_3", AnalysisOptions(dcm_widening=3.0))):
        best = float("inf")
        for _ in range(repeats):
            start = time.perf_counter()
            design_compensation(support, options)
            best = min(best, time.perf_counter() - start)
        out[name] = best
    return out


def streamed(stream: DcmStream, x: np.ndarray, block: int) -> np.ndarray:
    parts = [stream.process(x[i : i + block]) for i in range(0, x.size, block)]
    parts.append(stream.flush())
    return np.concatenate(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000_000)
    parser.add_argument("--block", type=int, default=65_536)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    dt = 1e-6
    b, a = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),)).discrete_tf(dt)
    design = design_compensation(ShotSupport(DiscreteModel(dt, a, b), supported_band_hz=(0.0, 38_000.0)))
    dcm = design.dcm
    rng = np.random.default_rng(0)
    x = signal.lfilter(b, a, rng.standard_normal(args.samples)) + 1e-3 * rng.standard_normal(args.samples)
    n, block = args.samples, args.block

    rates: dict[str, float] = {}
    rates["lfilter_whole"], baseline = best_rate(lambda: signal.lfilter(dcm.b, dcm.a, x), n, args.repeats)
    rates["apply_whole"], whole = best_rate(lambda: apply(dcm, x), n, args.repeats)
    rates["stream"], stream_out = best_rate(lambda: streamed(DcmStream(dcm), x, block), n, args.repeats)
    rates["stream_aligned"], aligned = best_rate(lambda: streamed(DcmStream(dcm, align=True), x, block), n,
                                                 args.repeats)
    scale = float(np.max(np.abs(baseline)))
    assert np.max(np.abs(stream_out - baseline)) <= 1e-9 * scale, "stream differs from lfilter"
    assert np.max(np.abs(whole - baseline)) <= 1e-9 * scale, "apply differs from lfilter"
    assert aligned.size == n
    for name, rate in rates.items():
        print(f"{name:<15} {rate / 1e6:9.1f} Msamples/s   x{rate / rates['lfilter_whole']:.2f} of lfilter whole")
    design_s = design_times(DiscreteModel(dt, a, b), args.repeats)
    print(f"design sized to the pulse {design_s['pulse']:.3f} s, with a fixed ×3 widening {design_s['widening_3']:.3f} s "
          f"(x{design_s['pulse'] / design_s['widening_3']:.2f})")
    print(json.dumps({
        "benchmark": "compensate",
        "samples": n,
        "block_samples": block,
        "dcm_order": dcm.order,
        "band_limit_taps": 0 if dcm.fir is None else int(dcm.fir.size),
        "samples_per_s": {k: round(v) for k, v in rates.items()},
        "ratio_to_lfilter_whole": {k: round(v / rates["lfilter_whole"], 3) for k, v in rates.items()},
        "design_s": {k: round(v, 4) for k, v in design_s.items()},
        "design_ratio_pulse_to_widening_3": round(design_s["pulse"] / design_s["widening_3"], 3),
    }))


if __name__ == "__main__":
    main()
