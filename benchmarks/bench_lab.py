"""The lab's record: what recording a shot adds to it, and how fast a sensor's history opens,
each against the database's own round trip (SELECT 1) in the same run.

    python benchmarks/bench_lab.py [--shots 30] [--calibrations 1000] [--postgresql]

Recording a shot is what the recorder does after STORE and ANALYSE (rig.lab_record): read the
shot file (meta, raw channels, analysis), hash the raw channels and the file, and write the
shot, its analysis and the audit entries in one transaction. The shot files are the simulated
rig's size (3 channels × 200 000 int16 samples). The recorder runs on its own thread, so the
sequencer does not wait for it; the figure is what it costs all the same. The history: 1 000
calibrations of one serial, read (one query) and judged (drift, conformity, due date).
SQLite by default; --postgresql also runs it on a throw-away PostgreSQL cluster (as the tests
start one). Last line: one JSON object.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hopkinson.lab.history import sensor_history
from hopkinson.lab.repository import open_repository
from hopkinson.rig.lab_record import LabRecorder, shot_record
from hopkinson.rig.shotfile import RawShot, ShotMeta
from hopkinson.rig.shotfile_writer import add_analysis, write_raw_shot

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.lab.pg_cluster import ClusterUnavailable, new_postgres_database, throwaway_cluster  # noqa: E402
from tests.lab.records import made_up_record, made_up_results  # noqa: E402

SAMPLES = 200_000  # the simulated rig's record length


def median_ms(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def make_shots(folder: Path, n: int) -> list[Path]:
    rng = np.random.default_rng(1)
    paths = []
    for i in range(n):
        raw = RawShot({role: (rng.integers(-8000, 8000, SAMPLES).astype(np.int16), 1e-3, 0.0)
                       for role in ("doppler", "doppler_quadrature", "response")}, 1e-8, 20_000)
        path = folder / f"shot-{i:03d}.h5"
        write_raw_shot(path, raw, ShotMeta("bench", "ACC", "SN-BENCH", 2.0, 3))
        add_analysis(path, made_up_results(1.0 + 1e-4 * i, 0.002))
        paths.append(path)
    return paths


def run(url: str, shots: list[Path], calibrations: int) -> dict[str, float]:
    with open_repository(url) as repo:
        round_trip = median_ms(repo.ping, 50)
        recorder = LabRecorder(url)
        record = [recorder.record_now(p) for p in shots[:1]]  # warm: imports, connection
        assert record == ["new"], record
        it = iter(shots[1:])
        record_ms = median_ms(lambda: recorder.record_now(next(it)), len(shots) - 1)
        recorder.close()
        read_ms = median_ms(lambda: shot_record(shots[0]), 10)
        for i in range(calibrations):
            repo.record_shot(made_up_record("SN-HIST", utc=f"20{10 + i // 365:02d}-01-01T00:00:00Z",
                                            sensitivity=1.0 + 1e-4 * (i % 7)))

        def history() -> None:
            sensor = repo.sensor("SN-HIST")
            judged = sensor_history(sensor, repo.calibrations("SN-HIST"))
            assert len(judged.calibrations) == calibrations

        history_ms = median_ms(history, 5)
    return {"round_trip_ms": round_trip, "record_shot_ms": record_ms, "read_shot_file_ms": read_ms,
            "history_ms": history_ms, "record_per_round_trip": record_ms / round_trip,
            "history_per_round_trip": history_ms / round_trip}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shots", type=int, default=30)
    parser.add_argument("--calibrations", type=int, default=1000)
    parser.add_argument("--postgresql", action="store_true", help="also on a throw-away PostgreSQL cluster")
    args = parser.parse_args()
    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        shots = make_shots(folder, args.shots)
        print(f"{args.shots} shot files of {shots[0].stat().st_size / 1e6:.1f} MB; {args.calibrations} calibrations")
        out["sqlite"] = run(f"sqlite:///{folder / 'lab.sqlite'}", shots, args.calibrations)
        if args.postgresql:
            try:
                with throwaway_cluster() as server:
                    out["postgresql"] = run(new_postgres_database(server), shots, args.calibrations)
            except ClusterUnavailable as exc:
                print(f"postgresql: skipped ({exc})")
    for name, figures in out.items():
        print(f"{name:<10} round trip {figures['round_trip_ms']:.3f} ms; recording a shot "
              f"{figures['record_shot_ms']:.1f} ms (x{figures['record_per_round_trip']:.0f}; reading the file "
              f"{figures['read_shot_file_ms']:.1f} ms of it; limit 50 ms); history of {args.calibrations} "
              f"{figures['history_ms']:.1f} ms (x{figures['history_per_round_trip']:.0f}; limit 200 ms)")
    print(json.dumps({"benchmark": "lab", "shots": args.shots, "calibrations": args.calibrations,
                      **{name: {k: round(v, 3) for k, v in f.items()} for name, f in out.items()}}))


if __name__ == "__main__":
    main()
