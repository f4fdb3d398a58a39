"""Golden outputs of the analysis commands (issue 46 item 1; docs/golden-outputs.md).

    .venv/bin/python tests/golden/make_golden.py               # (re)write tests/golden/outputs/*.json
    .venv/bin/python tests/golden/make_golden.py --stack       # this numerical stack's own set of the same goldens
    .venv/bin/python tests/golden/make_golden.py --check       # recompute and compare, name the first difference
    .venv/bin/python tests/golden/make_golden.py --out DIR     # write elsewhere (tests/golden/test_golden.py)
    .venv/bin/python tests/golden/make_golden.py --only ptb-   # the goldens whose name starts so

Each golden is the JSON a `hopkinson` command prints with --json (run in this process through
its real parser, `hopkinson.rig.cli.main.main`), or the analysis a shot file stores, on fixed
inputs: PTB's real record and sine calibration (tests/ptb_shock.py), the hybrids of PTB's
reference driving a known sensor (tests/analysis/ptb_hybrids.py), the known-model corpus
of the robustness suite (tests/analysis/hard_records.py, tests/analysis/test_robustness.py) and
three simulated shots of config/sim.toml's world (drivers/sim/world.simulate_shot) stored as
shot files. Every Monte Carlo run has a fixed seed; the BLAS runs on one thread (a threaded sum
rounds differently).

Normalised before saving (`normalised`): the working folder in any string becomes "<work>";
the keys in VOLATILE_KEYS (wall-clock times, CPU seconds, the installed version, generated
uuids) are dropped wherever they occur. Floats are written as Python's repr (exact: the text
round-trips to the same double). A golden is compared as text: bit-identical or different.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import platform
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
OUTPUTS = Path(__file__).resolve().parent / "outputs"
PLATFORM_FILE = "_platform.json"  # the numerical stack the goldens were made on (not a golden)
# Other numerical stacks' sets of the same goldens, one folder each (named by `stack_id`), made from a
# tree whose outputs/ is current (`--stack`): bit-identity holds per stack, so a refactor is checked
# on every stack that has a set. Making outputs/ again (a change of the method) removes them all.
STACKS = OUTPUTS / "stacks"
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
VOLATILE_KEYS = frozenset({"utc_time", "software_version", "uuid", "cpu_s", "elapsed_s", "created_utc"})
DRAWS = "50"  # the CLI's smallest: goldens check the arithmetic, not the intervals' stability

Golden = tuple[str, Any]  # (name, JSON object)


# ---------------------------------------------------------------------------------- normalising
def normalised(obj: Any, work: Path) -> Any:
    """`obj` with the working folder replaced by "<work>" in every string and the volatile keys
    dropped (module docstring)."""
    if isinstance(obj, dict):
        return {k: normalised(v, work) for k, v in obj.items() if k not in VOLATILE_KEYS}
    if isinstance(obj, list | tuple):
        return [normalised(v, work) for v in obj]
    if isinstance(obj, str):
        return obj.replace(str(work), "<work>")
    return obj


def golden_text(obj: Any) -> str:
    """The saved text of a golden: sorted keys, one level per indent, exact floats."""
    return json.dumps(obj, sort_keys=True, indent=1, ensure_ascii=False, allow_nan=True) + "\n"


def first_difference(expected: Any, actual: Any, path: str = "$") -> str | None:
    """The JSON path of the first place two objects differ, with both values; None if equal."""
    if type(expected) is not type(actual):
        return f"{path}: {_short(expected)} (golden) != {_short(actual)} (now)"
    if isinstance(expected, dict):
        for key in sorted(set(expected) | set(actual)):
            if key not in actual:
                return f"{path}.{key}: in the golden, missing now"
            if key not in expected:
                return f"{path}.{key}: new, not in the golden ({_short(actual[key])})"
            if (found := first_difference(expected[key], actual[key], f"{path}.{key}")) is not None:
                return found
        return None
    if isinstance(expected, list):
        for i, (e, a) in enumerate(zip(expected, actual, strict=False)):
            if (found := first_difference(e, a, f"{path}[{i}]")) is not None:
                return found
        if len(expected) != len(actual):
            return f"{path}: {len(expected)} items in the golden, {len(actual)} now"
        return None
    if expected != expected and actual != actual:  # NaN in both
        return None
    return None if expected == actual else f"{path}: {_short(expected)} (golden) != {_short(actual)} (now)"


def _short(value: Any) -> str:
    text = json.dumps(value, allow_nan=True)
    return text if len(text) <= 120 else text[:117] + "..."


def compare_texts(name: str, expected: str, actual: str) -> str | None:
    """None when the texts are equal; else which golden and where its JSON first differs."""
    if expected == actual:
        return None
    where = first_difference(json.loads(expected), json.loads(actual)) or "same JSON, different text"
    return f"{name}: {where}"


def platform_fingerprint() -> dict[str, Any]:
    """The numerical stack bit-identity depends on: Python, NumPy, SciPy, their BLAS, the CPU's
    SIMD extensions NumPy found (OpenBLAS picks its kernels by the CPU too)."""
    import numpy
    import scipy

    np_config = numpy.show_config(mode="dicts")
    sp_config = scipy.show_config(mode="dicts")
    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "numpy_blas": np_config["Build Dependencies"]["blas"].get("version"),
        "scipy_blas": sp_config["Build Dependencies"]["blas"].get("version"),
        "simd_found": np_config["SIMD Extensions"].get("found"),
    }


# --------------------------------------------------------------------------------- the commands
def hopkinson(*argv: Any) -> Any:
    """Run `hopkinson ARGV --json` in this process; its JSON object (exit code 0 required)."""
    from hopkinson.rig.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    words = [str(a) for a in argv] + ["--json"]
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(words)
    if code != 0:
        raise RuntimeError(f"hopkinson {' '.join(words)}: exit {code}: {err.getvalue().strip()}")
    return json.loads(out.getvalue())


def file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_npz(path: Path, record: Any) -> Path:
    """A record as the interchange NPZ (exact doubles, no CSV rounding)."""
    import numpy as np

    np.savez(path, time_s=record.time_s, reference=record.reference, response=record.response)
    return path


# ---------------------------------------------------------------------------------- the inputs
def ptb_goldens(work: Path) -> Iterator[Golden]:
    """PTB's record and sine calibration through identify (with its uncertainty), the paper's
    method, the joint sine fit, dcm, compare-sine (with the DCM) and compensate."""
    from tests.ptb_shock import write_ptb_record_csv, write_ptb_sine_csv

    record, sine = write_ptb_record_csv(work / "ptb.csv"), write_ptb_sine_csv(work / "ptb_sine.csv")
    model, dcm, compensated = work / "ptb-model.json", work / "ptb-dcm.json", work / "ptb-compensated.csv"
    yield "ptb-identify", hopkinson("identify", record, "--draws", DRAWS, "--seed", "1", "-o", model)
    yield "ptb-identify-model-file", json.loads(model.read_text(encoding="utf-8"))
    yield "ptb-identify-paper", hopkinson("identify", record, "--method", "paper")
    yield "ptb-identify-sine", hopkinson("identify", record, "--sine", sine, "--no-uncertainty")
    yield "ptb-dcm", hopkinson("dcm", "--model", model, "--record", record, "-o", dcm)
    yield "ptb-dcm-file", json.loads(dcm.read_text(encoding="utf-8"))
    yield "ptb-compare-sine", hopkinson("compare-sine", model, sine, "--dcm", dcm)
    out = hopkinson("compensate", record, "--dcm", dcm, "-o", compensated)
    yield "ptb-compensate", {**out, "output_sha256": file_digest(compensated)}


HYBRIDS = {  # name -> (tension gain, compression gain, noise seed, motion after the pulse, draws)
    "hybrid-clean": (1.0, 1.0, 5, False, None),
    "hybrid-lobe-gain": (0.993, 1.0145, 1, False, DRAWS),
    "hybrid-motion": (1.0, 1.0, 5, True, None),
}


def hybrid_goldens(work: Path) -> Iterator[Golden]:
    """PTB's real reference driving a known sensor (tests/analysis/ptb_hybrids.py): clean,
    with the lobe-dependent gain PTB's record shows (with its uncertainty), with the bar's motion."""
    from tests.analysis.ptb_hybrids import hybrid_record, motion_record

    for name, (tension, compression, seed, motion, draws) in HYBRIDS.items():
        rec = motion_record(seed, tension, compression) if motion else hybrid_record(tension, compression, seed)[0]
        path = write_npz(work / f"{name}.npz", rec)
        options = ["--draws", draws, "--seed", "2"] if draws else ["--no-uncertainty"]
        yield name, hopkinson("identify", path, *options)


CORPUS = ("rising noise 1 %", "rising noise 10 %", "interferometer noise on the reference", "delay of −3 samples",
          "baseline drift", "bipolar pulse", "truncated record", "second mode beyond the excitation",
          "amplifier low-pass in the band")


def corpus_goldens(work: Path) -> Iterator[Golden]:
    """Simulated sensors with a known model and the hard parts of real records (the robustness
    suite's cases, its seed 3), identified without the uncertainty."""
    from tests.analysis.hard_records import record
    from tests.analysis.test_robustness import CASES

    for i, title in enumerate(CORPUS, start=1):
        case, _ = CASES[title]
        path = write_npz(work / f"corpus-{i}.npz", record(case, 3))
        yield f"corpus-{i:02d}", {"case": title, **hopkinson("identify", path, "--no-uncertainty")}


SHOTS = ((1, 2.0, 1, None), (2, 3.5, 2, None), (3, 5.0, 3, DRAWS))  # projectile, bar, shot number, draws


def shot_goldens(work: Path) -> Iterator[Golden]:
    """Three shots of config/sim.toml's world (every realistic effect on, a quadrature
    interferometer) stored as shot files as the rig stores them: the analysis the shot's ANALYSE
    step stores (rig.shot.analyse_and_record, fixed seed), `hopkinson analyse` of the file again,
    and `hopkinson reduce` of it."""
    import dataclasses

    from hopkinson.analysis.options import AnalysisOverrides
    from hopkinson.rig.config import load_rig_config, load_sim_config
    from hopkinson.rig.shot import ShotRequest, analyse_and_record, analysis_params, shot_analyser
    from hopkinson.rig.shotfile import analysis_results, read_shot

    world = load_sim_config(REPO / "config" / "sim.toml").world
    config = load_rig_config(REPO / "config" / "rig-sim.toml")
    for projectile, pressure_bar, number, draws in SHOTS:
        name = f"sim-shot-{number}"
        path = write_sim_shot(work / f"{name}.h5", world, config, projectile, pressure_bar, number, draws)
        shot = read_shot(path)
        request = ShotRequest(pressure_bar, projectile, analysis=AnalysisOverrides(
            uncertainty=draws is not None, draws=None if draws is None else int(draws)))
        params = analysis_params(request, config, shot.meta.config["shot_settings"])
        recorded = analyse_and_record(path, shot.raw, dataclasses.replace(params, seed=number), shot_analyser(config))
        if recorded.error is not None:
            raise RuntimeError(f"{path}: {recorded.error}")
        yield f"{name}-analysis", analysis_results(path, 1)
        yield f"{name}-analyse-command", hopkinson("analyse", path, "--jobs", "1")
        yield f"{name}-reduce", hopkinson("reduce", path, "-o", work / f"{name}-record.npz")


def write_sim_shot(path: Path, world: Any, config: Any, projectile: int, pressure_bar: float, number: int,
                   draws: str | None) -> Path:
    """One simulated shot as a shot file: the channels quantised as the simulated digitizer sends
    them (int16 over each role's range), the rig's configuration snapshot, fixed identities."""
    from hopkinson.drivers.sim.scpi_instrument import quantise
    from hopkinson.drivers.sim.world import CaptureSettings, simulate_shot
    from hopkinson.rig.shot import digitizer_channels
    from hopkinson.rig.shotfile import RawChannel, RawShot, ShotMeta
    from hopkinson.rig.shotfile_writer import write_raw_shot

    d = config.digitizer
    pre_trigger = int(d.record_length * d.pre_trigger_fraction)
    volts, truth = simulate_shot(world, pressure_bar, projectile,
                                 CaptureSettings(d.sample_rate_hz, d.record_length, pre_trigger), shot_number=number)
    channels: dict[str, Any] = {}
    for role, channel in digitizer_channels(config).items():  # "CH1" -> the world's channel 1
        world_channel = int("".join(c for c in str(channel) if c.isdigit()))
        if world_channel in volts:
            codes, scale, zero = quantise(volts[world_channel], d.ranges_v[role], "int16")
            channels[role] = RawChannel(codes, scale, -zero * scale, code_range=(-32768.0, 32767.0))
    settings = {"amplifier_gain": truth["amplifier_gain"], "sensitivity_v_per_m_s2": config.analysis.sensitivity_v_per_m_s2,
                "analysis_options": {"uncertainty": False} if draws is None else {"uncertainty": True, "draws": int(draws)}}
    meta = ShotMeta(operator="golden", accelerometer_model="SIM", accelerometer_serial=str(number),
                    pressure_bar=pressure_bar, projectile=projectile, config={**config.snapshot(),
                                                                              "shot_settings": settings},
                    shot_id=f"s{number:03d}", simulated_truth=truth, uuid=f"00000000-0000-4000-8000-{number:012d}",
                    utc_time="2000-01-01T00:00:00Z", software_version="golden")
    return write_raw_shot(path, RawShot(channels, 1.0 / d.sample_rate_hz, pre_trigger), meta)


def plan_goldens(work: Path) -> Iterator[Golden]:
    """The bar model's shot planning for config/rig-sim.toml's bar."""
    yield "plan-shot", hopkinson("plan-shot", "--peak-g", "5000", "--sensor-fn-hz", "27000",
                                 "--config", REPO / "config" / "rig-sim.toml")


SOURCES: tuple[Callable[[Path], Iterator[Golden]], ...] = (
    ptb_goldens, hybrid_goldens, corpus_goldens, shot_goldens, plan_goldens)


def make(out: Path, only: str = "") -> dict[str, str]:
    """Compute every golden (those whose name starts with `only`), write each normalised text to
    `out/<name>.json` and the platform's fingerprint beside them; name -> text."""
    out.mkdir(parents=True, exist_ok=True)
    if out.resolve() == OUTPUTS:
        if not only:  # a golden no longer made leaves no stale file behind
            for stale in out.glob("*.json"):
                stale.unlink()
        shutil.rmtree(STACKS, ignore_errors=True)  # the other stacks' sets hold what the method made before
    texts: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="golden-") as folder:
        work = Path(folder).resolve()
        for source in SOURCES:
            for name, obj in source(work):
                if name.startswith(only):
                    texts[name] = golden_text(normalised(obj, work))
    for name, text in texts.items():
        (out / f"{name}.json").write_text(text, encoding="utf-8")
    (out / PLATFORM_FILE).write_text(golden_text(platform_fingerprint()), encoding="utf-8")
    return texts


def saved_goldens(folder: Path = OUTPUTS) -> dict[str, str]:
    """name -> text of the goldens saved in `folder` (the platform file left out)."""
    return {p.stem: p.read_text(encoding="utf-8") for p in sorted(folder.glob("*.json")) if p.name != PLATFORM_FILE}


def platform_difference(folder: Path = OUTPUTS, now: dict[str, Any] | None = None) -> str | None:
    """How this numerical stack (`now`: its fingerprint as saved, when the caller has it) differs
    from the one the goldens in `folder` were made on, or None."""
    saved = json.loads((folder / PLATFORM_FILE).read_text(encoding="utf-8"))
    return first_difference(saved, now if now is not None else json.loads(golden_text(platform_fingerprint())))


def stack_id(fingerprint: dict[str, Any]) -> str:
    """A stack set's folder name: the machine, its SIMD level and a digest of the whole fingerprint."""
    digest = hashlib.sha256(golden_text(fingerprint).encode()).hexdigest()[:10]
    simd = "-".join(str(s) for s in fingerprint.get("simd_found") or ()) or "nosimd"
    return f"{fingerprint.get('machine', 'cpu')}-{simd}-{digest}".lower()


def golden_sets() -> list[Path]:
    """outputs/ and every other stack's set (each folder holding a platform file)."""
    others = sorted(p for p in STACKS.iterdir() if (p / PLATFORM_FILE).is_file()) if STACKS.is_dir() else []
    return [OUTPUTS, *others]


def own_set() -> Path | None:
    """The set made on this numerical stack, or None (the stack's fingerprint taken once)."""
    now = json.loads(golden_text(platform_fingerprint()))
    return next((folder for folder in golden_sets() if platform_difference(folder, now) is None), None)


def not_this_stack() -> str:
    """Why no set is this stack's: how it differs from outputs/', and how many other sets there are."""
    others = len(golden_sets()) - 1
    return (f"another numerical stack than the goldens' ({platform_difference()})"
            + (f" and than the {others} other stacks' sets in {STACKS.relative_to(REPO)}" if others else ""))


def check(only: str = "") -> list[str]:
    """Recompute and compare with this stack's set (outputs/ where none is): one line per golden
    that differs (the first line says so when no set is this numerical stack's own)."""
    folder = own_set()
    with tempfile.TemporaryDirectory(prefix="golden-out-") as work:
        now = make(Path(work), only)
    saved = {k: v for k, v in saved_goldens(folder or OUTPUTS).items() if k.startswith(only)}
    problems = [f"{name}: saved, but no longer made" for name in sorted(set(saved) - set(now))]
    problems += [f"{name}: made, but no golden saved" for name in sorted(set(now) - set(saved))]
    problems += [p for name in sorted(set(saved) & set(now)) if (p := compare_texts(name, saved[name], now[name]))]
    if problems and folder is None:
        problems.insert(0, f"({not_this_stack()})")
    return problems


def make_stack_set() -> Path:
    """This stack's own set of the goldens outputs/ holds, in STACKS/<stack_id>; refused where
    outputs/ is this stack's already or the goldens made now are not the ones outputs/ names."""
    if platform_difference() is None:
        raise SystemExit("make_golden.py --stack: outputs/ was made on this numerical stack; nothing to add")
    folder = STACKS / stack_id(platform_fingerprint())
    shutil.rmtree(folder, ignore_errors=True)  # a golden no longer made leaves no stale file behind
    texts = make(folder)
    if sorted(texts) != sorted(saved_goldens()):
        shutil.rmtree(folder)
        raise SystemExit("make_golden.py --stack: this tree makes other goldens than outputs/ holds; "
                         "make outputs/ first")
    return folder


def main(argv: list[str] | None = None) -> int:
    for name in BLAS_THREAD_VARIABLES:  # before NumPy loads: a threaded BLAS sum rounds differently
        os.environ[name] = "1"
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))  # `tests.…` from any working folder
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=OUTPUTS, help="folder for the goldens (default %(default)s)")
    p.add_argument("--only", default="", metavar="PREFIX", help="only the goldens whose name starts so")
    p.add_argument("--check", action="store_true", help="compare with the saved goldens instead of writing")
    p.add_argument("--stack", action="store_true",
                   help=f"add this numerical stack's own set of outputs/' goldens (in {STACKS.relative_to(REPO)})")
    args = p.parse_args(argv)
    if args.stack:
        print(f"this numerical stack's goldens written to {make_stack_set()}")
        return 0
    if args.check:
        problems = check(args.only)
        print("\n".join(problems) if problems else "every golden output is bit-identical")
        return 1 if problems else 0
    texts = make(args.out, args.only)
    print(f"{len(texts)} golden outputs written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
