"""Every input failure is one line and exit 2 (issue 18): a symlink loop, a truncated NPZ, JSON
nested 100 000 deep, a time column in µs read as seconds (the step found is named), a
header-only CSV without numpy's warnings. Each case once through each command that reads it."""

from __future__ import annotations

import io
import json
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.model import DiscreteModel
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.rig.cli.main import main


def _record(path: Path, step_s: float = 1e-6, n: int = 2000) -> Path:
    t = np.arange(n) * step_s
    pulse = np.exp(-(((np.arange(n) - 500) / 60.0) ** 2))
    np.savetxt(path, np.column_stack([t, 1e5 * pulse, pulse]), delimiter=",", header="time_s,reference,response",
               comments="")
    return path


def _one_line(capsys) -> str:
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err, captured.err
    assert captured.err.startswith("hopkinson: error: ")
    return captured.err


@pytest.fixture
def bad(tmp_path: Path, capsys) -> dict[str, Path]:
    loop = tmp_path / "loop.csv"
    os.symlink(loop, loop)  # points at itself
    good = _record(tmp_path / "good.csv")
    buffer = io.BytesIO()
    np.savez(buffer, time_s=np.arange(4000) * 1e-6, reference=np.ones(4000), response=np.ones(4000))
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(buffer.getvalue()[: len(buffer.getvalue()) // 2])
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    micro = _record(tmp_path / "micro.csv", step_s=1.0)  # a time column in µs, read as seconds
    header_only = tmp_path / "header.csv"
    header_only.write_text("time_s,reference,response\n")
    sine = tmp_path / "sine.csv"
    sine.write_text("frequency_hz,magnitude,phase_deg\n1000,1,0\n2000,1,-1\n")
    b, a = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),)).discrete_tf(1e-6)
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"model": DiscreteModel(1e-6, a, b).to_dict(), "supported_band_hz": [0.0, 36_000.0]}))
    dcm = tmp_path / "dcm.json"
    assert main(["dcm", "--model", str(model), "-o", str(dcm)]) == 0  # a good DCM, for the record cases
    capsys.readouterr()
    return {"loop": loop, "good": good, "dcm": dcm, "truncated": truncated, "deep": deep, "micro": micro,
            "header": header_only, "sine": sine, "out": tmp_path / "out.csv", "tmp": tmp_path}


@pytest.mark.parametrize("argv, words", [
    (["reduce", "{loop}", "-o", "{out}"], "{loop}"),
    (["compensate", "{loop}", "--dcm", "{dcm}", "-o", "{out}"], "{loop}"),
    (["identify", "{truncated}"], "not a readable NPZ file"),
    (["reduce", "{truncated}", "-o", "{out}"], "not a readable NPZ file"),
    (["dcm", "--model", "{deep}"], "nested too deeply"),
    (["compensate", "{good}", "--dcm", "{deep}", "-o", "{out}"], "nested too deeply"),
    (["compare-sine", "{deep}", "{sine}"], "nested too deeply"),
    (["identify", "{micro}"], "time_s steps by 1 s, implausible for a shock record"),
    (["compensate", "{micro}", "--dcm", "{dcm}", "-o", "{out}"], "implausible for a shock record"),
    (["compensate", "{truncated}", "--dcm", "{dcm}", "-o", "{out}"], "not a readable NPZ file"),
    (["identify", "{header}"], "no data rows"),
])
def test_each_bad_input_is_one_line_and_exit_2(bad, capsys, argv, words) -> None:
    def fill(text: str) -> str:
        for name, path in bad.items():
            text = text.replace("{" + name + "}", str(path))
        return text

    assert main([fill(a) for a in argv]) == 2
    assert fill(words) in _one_line(capsys)
    assert not bad["out"].exists()


def test_a_truncated_npz_is_not_a_zip_the_reader_can_use(bad) -> None:
    assert not zipfile.is_zipfile(bad["truncated"])  # the fixture's damage is real


def test_a_reader_that_goes_away_ends_the_command_quietly(bad) -> None:
    # issue 18: `hopkinson … | head` printed "hopkinson: error: Broken pipe"
    import subprocess
    import sys

    f = np.linspace(100.0, 20_000.0, 4000)
    sine = bad["tmp"] / "long-sine.csv"
    np.savetxt(sine, np.column_stack([f, np.ones_like(f), np.zeros_like(f)]), delimiter=",",
               header="frequency_hz,magnitude,phase_deg", comments="")
    model = bad["tmp"] / "model.json"
    proc = subprocess.Popen([sys.executable, "-m", "hopkinson", "compare-sine", str(model), str(sine)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout.readline()  # the first line, then the reader goes away
    proc.stdout.close()
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 141 and err == b"", err  # 128 + SIGPIPE, nothing on stderr
