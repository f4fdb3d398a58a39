"""Benchmark: the loss of every order from one factorisation, and the whole identification.

Data: a 4th-order simulated accelerometer (27 kHz / ζ 0.05 and 70 kHz / ζ 0.03 resonances) at
1 MS/s, driven by a train of 10 µs half-sine shocks every 5 ms, 40 dB white noise on the
response and on the reference.

1. Loss ||g2||² of ARX orders 1 … 30. Baseline, measured in the same run: one
   numpy.linalg.lstsq per order on the explicit regression matrix (same rows). Ours: the Gram
   matrix of the augmented information matrix from lagged dot products + one Cholesky
   (analysis.loss, "cholesky"), and the accurate fallback, a blocked QR ("qr"). At 1 000 000
   samples the lstsq sweep would take minutes, so lstsq is timed on orders 1, N/3, 2N/3, N
   (1, 10, 20, 30) and the sweep's time interpolated (cost ∝ L·(2n+1)² fitted to those four;
   flagged "estimated").
2. Whole identification (analysis.identify: resample check, delay, bias-corrected fits of
   every order with order choice at the knee, final fit). Baseline: plain least squares
   swept over orders 1 … 12 (one lstsq each) — faster to run, but biased; pole error is the
   relative error of the s-plane poles ln(p)/T against the truth.

3. The whole command (issue 10): `hopkinson identify RECORD --max-order 30 --no-uncertainty` on
   200 000 samples, run as a user runs it (a fresh interpreter: imports included), against the
   paper's literal scan measured in the same run: one QR per order 1 … 30 of the augmented
   regression matrix [Φ_n, y] (numpy.linalg.qr, mode "r": R holds the parameters and the
   loss; the matrices built per order as the literal method does). Aim: at most 0.1×, in wall
   time and in CPU time (the CPU ratio is the steadier one on a shared machine). The same
   command with its uncertainty (default draws) is timed beside it.
4. How the cost grows with the record's length (issue 43): the CPU time of the identification,
   of its record preparation and of the noise stage within it (quiet stretches, the bar's
   motion, noise spectra) at each size, and the exponent p of t ∝ length^p between the sizes
   (1: linear). The preparation's DFT of the fitted window costs more than n·log n where the
   window's length is not a fast FFT length (the 10⁶-sample train: 995 889 samples, the record
   ending before the next fast length). The motion scan
   (analysis.noise.first_motion) against the literal one it replaces (is_motion on every tail of
   every stretch, as identify did until issue 43), on the same record in the same run.

BLAS runs on one thread (OPENBLAS_NUM_THREADS=1, set before numpy loads unless already set):
on a shared machine threaded BLAS-1 calls can be 50× slower and the figures meaningless.

    .venv/bin/python benchmarks/bench_identify.py [--sizes 200000,1000000] [--repeats 3]

Prints the figures and, on its last line, one JSON object.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import linear_sum_assignment  # noqa: E402

from hopkinson.analysis.identify import identify  # noqa: E402
from hopkinson.analysis.loss import arx_fit, arx_loss_by_order  # noqa: E402
from hopkinson.analysis.noise import first_motion, is_motion  # noqa: E402
from hopkinson.analysis.records import Record  # noqa: E402
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode, white_noise  # noqa: E402
from hopkinson.drivers.sim.shock import half_sine_m_s2  # noqa: E402

DT = 1e-6
TRUTH = AccelerometerTruth(modes=(Mode(27_000.0, 0.05), Mode(70_000.0, 0.03)))
PULSE_SPACING = 5000  # samples between shocks


def shock_train(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(reference, response) of the truth to a train of half-sine shocks, 40 dB noise on both."""
    t = np.arange(n) * DT
    u = np.zeros(n)
    for k in range(max(1, n // PULSE_SPACING)):
        u += half_sine_m_s2(t, 10e-6, 1.0 if k % 2 == 0 else 0.7, (k * PULSE_SPACING + 100) * DT)
    rng = np.random.default_rng(seed)
    y = TRUTH.respond(u, DT)
    return u + white_noise(u, 40.0, rng), y + white_noise(y, 40.0, rng)


def best_time(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    """Shortest wall time of `repeats` calls, and the last result."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def best_cpu_time(fn: Callable[[], Any], repeats: int) -> float:
    """Shortest CPU time of this process over `repeats` calls (steadier than wall time on a
    machine shared with other work)."""
    best = float("inf")
    for _ in range(repeats):
        start = time.process_time()
        fn()
        best = min(best, time.process_time() - start)
    return best


def lstsq_loss(u: np.ndarray, y: np.ndarray, order: int, max_order: int) -> float:
    """One numpy.linalg.lstsq: the ARX loss of `order` over the augmented matrix's rows."""
    rows = u.size - max_order
    t = np.arange(order, order + rows)
    phi = np.column_stack([-y[t - i] for i in range(1, order + 1)] + [u[t - i] for i in range(order + 1)])
    theta, *_ = np.linalg.lstsq(phi, y[t], rcond=None)
    r = y[t] - phi @ theta
    return float(r @ r)


def pole_error(poles: np.ndarray) -> float:
    """Largest relative s-plane error of the truth's poles against the estimated ones (optimal
    pairing; an order above the truth's leaves its extra poles unpaired, one below it is inf)."""
    est = np.log(np.asarray(poles, dtype=complex)) / DT
    true = np.log(TRUTH.discrete_poles(DT)) / DT
    if est.size < true.size:
        return float("inf")
    cost = np.abs(est[:, None] - true[None, :]) / np.abs(true[None, :])
    rows, cols = linear_sum_assignment(cost)
    return float(np.max(cost[rows, cols]))


def probe_orders(max_order: int) -> list[int]:
    """The orders lstsq is timed on when the whole sweep would take too long."""
    return sorted({1, max_order // 3, 2 * max_order // 3, max_order})


def bench_losses(u: np.ndarray, y: np.ndarray, max_order: int, repeats: int, full_baseline: bool) -> dict[str, Any]:
    chol_s, chol = best_time(lambda: arx_loss_by_order(u, y, max_order, method="cholesky"), repeats)
    qr_s, qr = best_time(lambda: arx_loss_by_order(u, y, max_order, method="qr"), 1)
    if full_baseline:
        t0 = time.perf_counter()
        ref = np.array([lstsq_loss(u, y, n, max_order) for n in range(1, max_order + 1)])
        lstsq_s, estimated = time.perf_counter() - t0, False
        agree = {"cholesky": float(np.max(np.abs(chol / ref - 1))), "qr": float(np.max(np.abs(qr / ref - 1)))}
    else:
        probe = probe_orders(max_order)
        times, ref_probe = [], []
        for n in probe:
            t0 = time.perf_counter()
            ref_probe.append(lstsq_loss(u, y, n, max_order))
            times.append(time.perf_counter() - t0)
        # Fit t(n) = c0 + c1·(2n+1)² to the probes, sum over every order.
        x = np.array([(2 * n + 1) ** 2 for n in probe], dtype=float)
        c1, c0 = np.polyfit(x, np.array(times), 1)
        lstsq_s = float(sum(max(c0 + c1 * (2 * n + 1) ** 2, 0.0) for n in range(1, max_order + 1)))
        estimated = True
        idx = [n - 1 for n in probe]
        ref_probe = np.array(ref_probe)
        agree = {"cholesky": float(np.max(np.abs(chol[idx] / ref_probe - 1))),
                 "qr": float(np.max(np.abs(qr[idx] / ref_probe - 1)))}
    return {
        "orders": max_order,
        "lstsq_per_order_s": lstsq_s,
        "lstsq_estimated": estimated,
        "one_factorisation_cholesky_s": chol_s,
        "one_factorisation_qr_s": qr_s,
        "speedup_cholesky": lstsq_s / chol_s,
        "speedup_qr": lstsq_s / qr_s,
        "max_rel_loss_difference_vs_lstsq": agree,
    }


def bench_identify(u: np.ndarray, y: np.ndarray, repeats: int) -> dict[str, Any]:
    record = Record(DT, u, y)
    ours_s, result = best_time(lambda: identify(record), repeats)
    ours_cpu_s = best_cpu_time(lambda: identify(record), repeats)

    def arx_sweep() -> tuple[np.ndarray, np.ndarray]:
        fits = [arx_fit(u, y, n) for n in range(1, 13)]
        return fits[3]

    base_s, (a_arx, _) = best_time(arx_sweep, 1)
    ours_err = pole_error(result.poles)
    arx_err = pole_error(np.roots(a_arx))
    return {
        "identify_s": ours_s,
        "identify_cpu_s": ours_cpu_s,
        "order_chosen": result.order,
        "true_order": TRUTH.order,
        "pole_error": ours_err,
        "fit_percent": result.fit_percent,
        "baseline_arx_sweep_1_12_s": base_s,
        "baseline_arx_order4_pole_error": arx_err,
        "time_ratio_vs_arx_sweep": ours_s / base_s,
        "pole_error_ratio_arx_vs_ours": arx_err / ours_err if ours_err > 0 else float("inf"),
    }


def literal_qr_scan(u: np.ndarray, y: np.ndarray, max_order: int) -> np.ndarray:
    """The paper's literal per-order scan: for each order, build [Φ_n, y] and take one QR."""
    rows = u.size - max_order
    t = np.arange(max_order, max_order + rows)
    losses = []
    for n in range(1, max_order + 1):
        cols = [-y[t - i] for i in range(1, n + 1)] + [u[t - i] for i in range(n + 1)] + [y[t]]
        r = np.linalg.qr(np.column_stack(cols), mode="r")
        losses.append(float(r[-1, -1] ** 2))
    return np.array(losses)


def bench_command(u: np.ndarray, y: np.ndarray, max_order: int, repeats: int) -> dict[str, Any]:
    """The whole `hopkinson identify` command (fresh interpreter) against the literal QR scan."""
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    import hopkinson
    import hopkinson.analysis
    import hopkinson.rig
    from hopkinson.analysis.records import write_record

    # The package's byte code first, as `pip install` (or any first run that may write it) leaves it:
    # where PYTHONDONTWRITEBYTECODE is set, each command would compile its modules again (~0.5 s).
    folders = [str(Path(m.__file__).parent) for m in (hopkinson, hopkinson.analysis, hopkinson.rig)]
    subprocess.run([sys.executable, "-m", "compileall", "-q", *folders], check=True, capture_output=True)
    with tempfile.TemporaryDirectory() as folder:
        path = write_record(f"{folder}/train.npz", Record(DT, u, y))
        base = [sys.executable, "-m", "hopkinson", "identify", str(path), "--max-order", str(max_order), "--json"]

        cpu: list[float] = []

        def run_command(extra: list[str]) -> dict[str, Any]:
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            done = subprocess.run(base + extra, capture_output=True, text=True, check=True)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
            return json.loads(done.stdout)

        command_s, result = best_time(lambda: run_command(["--no-uncertainty"]), repeats)
        command_cpu_s = min(cpu)
        with_unc_s, with_unc = best_time(lambda: run_command(["--seed", "1"]), 1)
    scan_cpu: list[float] = []

    def timed_scan() -> None:
        start = time.process_time()
        literal_qr_scan(u, y, max_order)
        scan_cpu.append(time.process_time() - start)

    scan_s, _ = best_time(timed_scan, 2)
    scan_cpu_s = min(scan_cpu)
    return {
        "literal_qr_scan_s": scan_s,
        "literal_qr_scan_cpu_s": scan_cpu_s,
        "command_s": command_s,
        "command_cpu_s": command_cpu_s,
        "ratio": command_s / scan_s,
        "cpu_ratio": command_cpu_s / scan_cpu_s,
        "order_chosen": result["order"],
        "pole_error": pole_error(np.array([complex(*p) for p in result["poles"]])),
        "command_with_uncertainty_s": with_unc_s,
        "draws": (with_unc.get("uncertainty") or {}).get("draws"),
    }


def bench_preparation(u: np.ndarray, y: np.ndarray, max_order: int, repeats: int) -> tuple[float, float]:
    """Best CPU times of the record preparation (rate, realignment, the pulse, the noise stage,
    the band and its DFT) and of its noise stage (record_preparation.measure_noise: the quiet
    stretches, the bar's motion, the noise spectra)."""
    from hopkinson.analysis import record_preparation

    record = Record(DT, u, y)
    stage = record_preparation.measure_noise
    noise_cpu: list[float] = []

    def timed_stage(*args: Any) -> Any:
        start = time.process_time()
        out = stage(*args)
        noise_cpu.append(time.process_time() - start)
        return out

    record_preparation.measure_noise = timed_stage
    try:
        prep = best_cpu_time(lambda: record_preparation.prepare_record(record, 1.0 / DT, max_order, None, 32),
                             repeats)
    finally:
        record_preparation.measure_noise = stage
    return prep, min(noise_cpu)


def motion_stretches(u: np.ndarray, y: np.ndarray, max_order: int) -> list[tuple[int, int]]:
    """The quiet stretches after the pulses that identify scans for motion, as (start, stop)."""
    from hopkinson.analysis import record_preparation

    seen: list[tuple[int, int]] = []
    scan = record_preparation.first_motion

    def recording(x: np.ndarray, z: np.ndarray, rate: float, onsets: list[int], stop: int) -> Any:
        seen.append((onsets[0], stop))
        return scan(x, z, rate, onsets, stop)

    record_preparation.first_motion = recording
    try:
        record_preparation.prepare_record(Record(DT, u, y), 1.0 / DT, max_order, None, 32)
    finally:
        record_preparation.first_motion = scan
    return seen


def bench_motion_scan(u: np.ndarray, y: np.ndarray, max_order: int) -> dict[str, Any]:
    """The motion scan over the stretches identify scans, against the literal scan (is_motion on
    every tail in turn), on the same normalised channels; both must find the same."""
    stretches = motion_stretches(u, y, max_order)
    x, z = (v / np.max(np.abs(v)) for v in (u, y))

    def onsets(start: int, stop: int) -> list[int]:
        return [start, *range(start + 64, stop - 320 + 1, 64)]

    def ours() -> list[Any]:
        return [first_motion(x, z, 1.0 / DT, onsets(a, b), b) for a, b in stretches]

    def literal() -> list[Any]:
        found = []
        for a, b in stretches:
            hit = None
            for onset in onsets(a, b):
                verdict, msc = is_motion(x[onset:b], z[onset:b], 1.0 / DT)
                if verdict:
                    hit = (onset, msc)
                    break
            found.append(hit)
        return found

    ours_s, mine = best_time(ours, 1)
    literal_s, theirs = best_time(literal, 1)
    return {"stretches": len(stretches), "samples_scanned": int(sum(b - a for a, b in stretches)),
            "scan_s": ours_s, "literal_scan_s": literal_s, "speedup": literal_s / ours_s, "same_result": mine == theirs}


def growth_exponent(n1: int, t1: float, n2: int, t2: float) -> float:
    """p in t ∝ n^p between two sizes."""
    return math.log(t2 / t1) / math.log(n2 / n1)


def run(sizes: list[int], max_order: int = 30, repeats: int = 3) -> dict[str, Any]:
    """All figures for the given record sizes; prints them as it goes."""
    out: dict[str, Any] = {"benchmark": "identify", "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS")}
    for n in sizes:
        u, y = shock_train(n)
        full = n <= 200_000
        losses = bench_losses(u, y, max_order, repeats, full)
        probed = ", ".join(str(k) for k in probe_orders(max_order))
        est = f" (estimated from orders {probed})" if losses["lstsq_estimated"] else ""
        print(f"{n} samples — loss of orders 1..{max_order}:")
        print(f"  one lstsq per order{est}: {losses['lstsq_per_order_s']:.3f} s")
        print(f"  one factorisation, Cholesky: {losses['one_factorisation_cholesky_s'] * 1e3:.1f} ms "
              f"({losses['speedup_cholesky']:.0f}× faster); QR: {losses['one_factorisation_qr_s'] * 1e3:.0f} ms "
              f"({losses['speedup_qr']:.0f}×)")
        print(f"  largest relative difference from lstsq: {losses['max_rel_loss_difference_vs_lstsq']}")
        ident = bench_identify(u, y, repeats)
        print(f"{n} samples — identification: {ident['identify_s']:.3f} s, order {ident['order_chosen']} "
              f"(truth {ident['true_order']}), pole error {ident['pole_error']:.2e}, fit {ident['fit_percent']:.2f} %")
        print(f"  plain least squares, orders 1..12: {ident['baseline_arx_sweep_1_12_s']:.3f} s "
              f"(ours {ident['time_ratio_vs_arx_sweep']:.2f}× its time), its order-4 pole error "
              f"{ident['baseline_arx_order4_pole_error']:.2e} ({ident['pole_error_ratio_arx_vs_ours']:.0f}× ours)")
        prep_s, noise_s = bench_preparation(u, y, max_order, repeats)
        print(f"  CPU time: identification {ident['identify_cpu_s']:.3f} s, its record preparation {prep_s:.3f} s, "
              f"the noise stage among it {noise_s:.3f} s")
        out[str(n)] = {"loss_by_order": losses, "identification": ident, "preparation_cpu_s": prep_s,
                       "noise_stage_cpu_s": noise_s}
        if n == 200_000:
            cmd = bench_command(u, y, max_order, repeats)
            aim = "within" if max(cmd["ratio"], cmd["cpu_ratio"]) <= 0.1 else "ABOVE"
            print(f"{n} samples — `hopkinson identify --max-order {max_order}` (whole command, imports included): "
                  f"{cmd['command_s']:.2f} s = {cmd['ratio']:.3f}× the literal QR scan ({cmd['literal_qr_scan_s']:.2f} s); "
                  f"CPU {cmd['command_cpu_s']:.2f} s = {cmd['cpu_ratio']:.3f}× the scan's "
                  f"({cmd['literal_qr_scan_cpu_s']:.2f} s), {aim} the aim of 0.1×; order {cmd['order_chosen']}, pole "
                  f"error {cmd['pole_error']:.1e}; with the uncertainty ({cmd['draws']} draws) "
                  f"{cmd['command_with_uncertainty_s']:.2f} s")
            out[str(n)]["command"] = cmd
            motion = bench_motion_scan(u, y, max_order)
            print(f"{n} samples — motion scan over {motion['stretches']} quiet stretches of both channels "
                  f"({motion['samples_scanned']} samples): "
                  f"{motion['scan_s'] * 1e3:.0f} ms, the literal scan {motion['literal_scan_s']:.2f} s "
                  f"({motion['speedup']:.0f}× faster), the same result: {motion['same_result']}")
            out[str(n)]["motion_scan"] = motion
    if len(sizes) >= 2:
        n1, n2 = sizes[0], sizes[-1]
        growth = {
            "identification": growth_exponent(n1, out[str(n1)]["identification"]["identify_cpu_s"],
                                              n2, out[str(n2)]["identification"]["identify_cpu_s"]),
            "preparation": growth_exponent(n1, out[str(n1)]["preparation_cpu_s"], n2, out[str(n2)]["preparation_cpu_s"]),
            "noise_stage": growth_exponent(n1, out[str(n1)]["noise_stage_cpu_s"], n2, out[str(n2)]["noise_stage_cpu_s"]),
        }
        print(f"growth of the CPU time from {n1} to {n2} samples (t ∝ length^p; 1 is linear): identification "
              f"p = {growth['identification']:.2f}, record preparation p = {growth['preparation']:.2f}, its noise "
              f"stage p = {growth['noise_stage']:.2f}")
        out["growth_exponent"] = growth
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="200000,1000000", help="record lengths, comma-separated")
    parser.add_argument("--max-order", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    result = run([int(s) for s in args.sizes.split(",")], args.max_order, args.repeats)
    print(json.dumps(finite_or_null(result), allow_nan=False))


def finite_or_null(value: Any) -> Any:
    """The result with every non-finite float as null (JSON has no inf or NaN)."""
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_or_null(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


if __name__ == "__main__":
    main()
