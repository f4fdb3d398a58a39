"""Two-channel record I/O: round trips and clear errors for bad files."""

from __future__ import annotations

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
