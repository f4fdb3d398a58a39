"""Two-channel record I/O: round trips and clear errors for bad files."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.errors import RecordError
from hopkinson.analysis.records import Record, read_record, record_from_arrays, write_record


def _record(n: int = 200) -> Record:
    t = 1e-6 * np.arange(n)
    return record_from_arrays(t, np.sin(2e4 * t), np.cos(3e4 * t))


@pytest.mark.parametrize("name", ["r.csv", "r.npz"])
def test_round_trip(tmp_path, name):
    rec = _record()
    back = read_record(write_record(tmp_path / name, rec))
    assert back.sample_interval_s == pytest.approx(1e-6, rel=1e-9)
    np.testing.assert_allclose(back.reference, rec.reference, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(back.response, rec.response, rtol=1e-9, atol=1e-12)


def test_missing_column_names_file_and_column(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("time_s,reference\n0,1\n1e-6,2\n")
    with pytest.raises(RecordError, match=r"bad\.csv.*missing column\(s\) response"):
        read_record(path)


def test_nan_is_reported_with_row(tmp_path):
    t = 1e-6 * np.arange(50)
    ref = np.ones(50)
    ref[17] = np.nan
    with pytest.raises(RecordError, match="NaN.*row 17"):
        record_from_arrays(t, ref, np.ones(50), source="x.csv")


def test_non_numeric_line_is_reported(tmp_path):
    path = tmp_path / "text.csv"
    path.write_text("time_s,reference,response\n0,1,2\n1e-6,abc,2\n")
    with pytest.raises(RecordError, match="not a numeric table.*abc"):
        read_record(path)


def test_non_uniform_time_is_rejected():
    t = np.cumsum(np.r_[0, np.full(40, 1e-6), 3e-6, np.full(40, 1e-6)])
    with pytest.raises(RecordError, match="uniformly sampled"):
        record_from_arrays(t, np.ones(t.size), np.ones(t.size))


def test_npz_missing_key(tmp_path):
    path = tmp_path / "k.npz"
    np.savez(path, time_s=np.arange(20.0), reference=np.ones(20))
    with pytest.raises(RecordError, match="missing key"):
        read_record(path)


def test_too_short_and_missing_file(tmp_path):
    with pytest.raises(RecordError, match="at least 16"):
        record_from_arrays(np.arange(5.0), np.ones(5), np.ones(5))
    with pytest.raises(RecordError, match="no such file"):
        read_record(tmp_path / "absent.csv")


# ---------------------------------------------------------------------------- units in the files


@pytest.mark.parametrize("name", ["r.csv", "r.npz"])
def test_units_travel_with_the_file(tmp_path, name):
    t = 1e-6 * np.arange(100)
    rec = record_from_arrays(t, np.sin(2e4 * t), np.cos(3e4 * t), response_unit="V")
    path = write_record(tmp_path / name, rec)
    if name.endswith(".csv"):
        assert path.read_text().splitlines()[0] == "time_s,reference [m/s^2],response [V]"
    back = read_record(path)
    assert back.response_unit == "V"
    np.testing.assert_allclose(back.response, rec.response, rtol=1e-9, atol=1e-12)
    assert read_record(write_record(tmp_path / f"none-{name}", _record())).response_unit is None


def test_a_header_without_units_still_reads_and_a_wrong_reference_unit_is_refused(tmp_path):
    path = tmp_path / "old.csv"
    t = 1e-6 * np.arange(20)
    path.write_text("time_s,reference,response\n" + "".join(f"{a},{a * 1e6},{a}\n" for a in t))
    assert read_record(path).response_unit is None and read_record(path).n_samples == 20
    path.write_text("time_s,reference [g],response [V]\n" + "".join(f"{a},{a * 1e6},{a}\n" for a in t))
    with pytest.raises(RecordError, match=r"old\.csv: the reference must be acceleration in m/s\^2.*'g'"):
        read_record(path)


# ---------------------------------------------------------------------------- bad input (issue 9)


def _rows(n: int, extra_at: int | None = None) -> str:
    lines = ["time_s,reference,response"]
    for i in range(n):
        lines.append(f"{i * 1e-6},{np.sin(i / 5)},{np.cos(i / 5)}" + (",7" if i == extra_at else ""))
    return "\n".join(lines) + "\n"


def test_bad_inputs_give_one_line_naming_the_file(tmp_path):
    folder = tmp_path / "folder.csv"
    folder.mkdir()
    huge = tmp_path / "huge.csv"
    huge.write_text(_rows(40).replace("time_s,reference,response", "time_s,reference,response," + "x" * 200_000))
    absurd = tmp_path / "absurd.csv"
    lines = _rows(40).splitlines()
    lines[6] = "5e-06,1e300,0.5"  # data row 5
    absurd.write_text("\n".join(lines) + "\n")
    extra = tmp_path / "extra.csv"
    extra.write_text(_rows(40, extra_at=30))
    wide = tmp_path / "wide.csv"
    wide.write_text(_rows(40).replace("\n", ",1\n").replace("response,1\n", "response\n"))
    cases = [
        (folder, "a folder, not a record file"),
        (Path("/dev/zero"), "not a regular file"),
        (huge, "the header line is longer than 64 KiB"),
        (absurd, r"column 'reference' has the value 1e\+300 at row 5"),
        (extra, "line 32 has 4 fields where the lines above have 3"),
        (wide, "the rows have 4 fields but the header names 3"),
    ]
    for path, reason in cases:
        with pytest.raises(RecordError) as info:
            read_record(path)
        message = str(info.value)
        assert message.startswith(f"{path}: ") and "\n" not in message
        assert re.search(reason, message), (path, message)


def test_the_commands_turn_bad_input_into_exit_2(tmp_path, capsys):
    from hopkinson.rig.cli.main import main

    extra = tmp_path / "extra.csv"
    extra.write_text(_rows(40, extra_at=30))
    for path in (extra, tmp_path):
        assert main(["identify", str(path)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and str(path) in err and "Traceback" not in err
