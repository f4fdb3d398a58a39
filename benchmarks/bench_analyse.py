"""Benchmark: `hopkinson analyse` on a lab's archive, serially and in parallel (issue 43).

Data: one shot fired on the simulated rig (2 ms at 100 MS/s, reduced to 1 MS/s, the shipped
simulator's realistic records), copied into a folder tree of N shot files (two years, a folder
each). Each run gets a fresh copy of the tree (a re-analysis adds a version to every file).

Baseline, in the same run: `hopkinson analyse TREE --jobs 1` (one shot after another, as the
command did before it took --jobs), on one core: BLAS single-threaded (OPENBLAS_NUM_THREADS,
OMP_NUM_THREADS, MKL_NUM_THREADS = 1, as the workers run it; threaded BLAS would let the
"serial" run use a second core in its least-squares solves). Ours: `--jobs J`, J the CPUs this
process may use (or --jobs). Both with the uncertainty at the default 400 draws (as a lab re-runs its archive) and
timed as a user runs them (a fresh interpreter: imports and worker start-up included). Prints
seconds per shot, the speed-up and the parallel efficiency (speed-up ÷ J). On a machine shared
with other work the wall-time speed-up is bounded by the cores actually free, not by J, so the
CPU seconds each shot took (serially, and in a worker: the `cpu_s` of each row) and the cores
each run obtained are printed too, and what J free cores give: J × (serial CPU a shot ÷ worker
CPU a shot, at most J).

    .venv/bin/python benchmarks/bench_analyse.py [--shots 8] [--jobs J] [--draws 400]

Prints the figures and, on its last line, one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HOPKINSON = [sys.executable, "-m", "hopkinson"]


def available_cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def fire_one_shot(folder: Path) -> Path:
    """One shot on the simulated rig (100× real time), analysed with its uncertainty: a
    re-analysis keeps the options of the first (the uncertainty among them)."""
    sim = folder / "sim-fast.toml"
    sim.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
    out = folder / "fired"
    subprocess.run([*HOPKINSON, "shot", "--sim", "--sim-config", str(sim), "--yes", "--out", str(out),
                    "--pressure-bar", "2.0"], check=True, capture_output=True, text=True)
    (shot,) = out.glob("*.h5")
    return shot


def archive(shot: Path, root: Path, count: int) -> Path:
    """A folder tree of `count` copies of the shot: root/<year>/<n>.h5."""
    for i in range(count):
        target = root / f"{2025 + i % 2}" / f"shot-{i:04d}.h5"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shot, target)
    return root


def time_analyse(shot: Path, folder: Path, count: int, jobs: int, draws: int) -> tuple[float, float, dict[str, Any]]:
    """Wall time and CPU time of `hopkinson analyse` over a fresh tree (the command's own: its
    workers are the fork server's children, not counted), and its JSON."""
    root = archive(shot, folder / f"tree-jobs{jobs}", count)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    one_thread = {name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    done = subprocess.run([*HOPKINSON, "analyse", str(root), "--jobs", str(jobs), "--draws", str(draws), "--json"],
                          capture_output=True, text=True, env={**os.environ, **one_thread})
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"hopkinson analyse --jobs {jobs} failed ({done.returncode}): {done.stderr.strip()}")
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return seconds, cpu, json.loads(done.stdout)


def estimates(row: dict[str, Any]) -> tuple[Any, ...]:
    """A shot's estimates (not their Monte Carlo uncertainty, drawn afresh in each run)."""
    kf = row["key_figures"]
    return (kf["order"], kf["sensitivity"]["value"], kf["natural_frequency_hz"]["value"],
            kf["damping_ratio"]["value"], kf["fbsd_hz"]["5"]["value"], kf["fbsd_hz"]["10"]["value"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shots", type=int, default=8)
    parser.add_argument("--jobs", type=int, default=available_cpus())
    parser.add_argument("--draws", type=int, default=400)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        shot = fire_one_shot(folder)
        serial_s, serial_cpu_s, serial = time_analyse(shot, folder, args.shots, 1, args.draws)
        parallel_s, parallel_cpu_s, parallel = time_analyse(shot, folder, args.shots, args.jobs, args.draws)
    same = [estimates(r) for r in serial["shots"]] == [estimates(r) for r in parallel["shots"]]
    serial_shot_cpu = sum(r["cpu_s"] for r in serial["shots"]) / args.shots
    parallel_shot_cpu = sum(r["cpu_s"] for r in parallel["shots"]) / args.shots
    # What J free cores give: J shots at a time, each at its own CPU cost in a worker, against one
    # at a time at its cost in the serial run (the worker start-up in the wall times, not here).
    on_free_cores = args.jobs * min(1.0, serial_shot_cpu / parallel_shot_cpu)
    with_u = all(r["key_figures"]["draws"] == args.draws for r in serial["shots"])
    speedup = serial_s / parallel_s
    print(f"{args.shots} shots, {args.draws} draws each: --jobs 1 {serial_s:.1f} s ({serial_s / args.shots:.2f} s a shot); "
          f"--jobs {args.jobs} {parallel_s:.1f} s ({parallel_s / args.shots:.2f} s a shot)")
    print(f"CPU a shot: {serial_shot_cpu:.2f} s serially, {parallel_shot_cpu:.2f} s in a worker; --jobs 1 had "
          f"{serial_cpu_s / serial_s:.2f} of a core, --jobs {args.jobs} "
          f"{parallel_shot_cpu * args.shots / parallel_s:.2f} cores (load average {os.getloadavg()[0]:.1f} on "
          f"{available_cpus()} CPUs); on {args.jobs} free cores: {on_free_cores:.2f}×")
    print(f"speed-up {speedup:.2f}× on {args.jobs} jobs (efficiency {speedup / args.jobs:.0%}); "
          f"the same estimates: {same}, each with its uncertainty: {with_u}; 10 000 shots at this rate: {parallel_s / args.shots * 1e4 / 3600:.1f} h "
          f"(serially {serial_s / args.shots * 1e4 / 3600:.1f} h)")
    print(json.dumps({"benchmark": "analyse", "shots": args.shots, "draws": args.draws, "jobs": args.jobs,
                      "cpus": available_cpus(), "serial_s": serial_s, "parallel_s": parallel_s,
                      "serial_s_per_shot": serial_s / args.shots, "parallel_s_per_shot": parallel_s / args.shots,
                      "serial_cpu_s_per_shot": serial_shot_cpu, "parallel_cpu_s_per_shot": parallel_shot_cpu,
                      "cores_used_serial": serial_cpu_s / serial_s,
                      "cores_used_parallel": parallel_shot_cpu * args.shots / parallel_s,
                      "speedup_on_free_cores": on_free_cores,
                      "load_average_1min": os.getloadavg()[0],
                      "speedup": speedup, "efficiency": speedup / args.jobs, "same_estimates": same,
                      "with_uncertainty": with_u},
                     allow_nan=False))


if __name__ == "__main__":
    main()
