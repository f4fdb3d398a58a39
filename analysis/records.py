"""Two-channel records (the interchange format): CSV or NPZ with time_s, reference, response.

The reference is acceleration in m/s²; the response is in any unit (V, m/s², counts).
Every reader validates what it loads and names the file and the problem when it cannot.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.errors import RecordError

RECORD_KEYS = ("time_s", "reference", "response")


@dataclass(frozen=True)
class Record:
    """A uniformly sampled two-channel record."""

    sample_interval_s: float
    reference: np.ndarray  # reference acceleration, m/s²
    response: np.ndarray  # accelerometer response (any unit)
    start_time_s: float = 0.0

    @property
    def n_samples(self) -> int:
        return int(self.reference.size)

    @property
    def time_s(self) -> np.ndarray:
        return self.start_time_s + self.sample_interval_s * np.arange(self.n_samples)

    @property
    def sample_rate_hz(self) -> float:
        return 1.0 / self.sample_interval_s


def record_from_arrays(
    time_s: np.ndarray, reference: np.ndarray, response: np.ndarray, source: str = "record"
) -> Record:
    """Validate three columns and build a Record; `source` names the data in errors."""
    cols = {}
    for key, col in zip(RECORD_KEYS, (time_s, reference, response), strict=True):
        arr = np.asarray(col, dtype=float).ravel()
        if not np.all(np.isfinite(arr)):
            bad = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise RecordError(f"{source}: column '{key}' has a NaN or infinite value at row {bad}")
        cols[key] = arr
    n = cols["time_s"].size
    if cols["reference"].size != n or cols["response"].size != n:
        raise RecordError(f"{source}: columns have different lengths")
    if n < 16:
        raise RecordError(f"{source}: only {n} samples; a record needs at least 16")
    dt = np.diff(cols["time_s"])
    step = float(np.median(dt))
    if not step > 0:
        raise RecordError(f"{source}: time_s is not increasing")
    if np.max(np.abs(dt - step)) > 1e-3 * step:
        raise RecordError(f"{source}: time_s is not uniformly sampled (step varies by more than 0.1 %)")
    return Record(step, cols["reference"], cols["response"], float(cols["time_s"][0]))


def read_record(path: str | Path) -> Record:
    """Read a CSV (header time_s,reference,response) or NPZ (same keys) record."""
    path = Path(path)
    if not path.exists():
        raise RecordError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as data:
                missing = [k for k in RECORD_KEYS if k not in data.files]
                if missing:
                    raise RecordError(f"{path}: missing key(s) {', '.join(missing)}; an NPZ record needs {', '.join(RECORD_KEYS)}")
                arrays = [np.asarray(data[k]) for k in RECORD_KEYS]
        except (OSError, ValueError) as exc:
            if isinstance(exc, RecordError):
                raise
            raise RecordError(f"{path}: not a readable NPZ file ({exc})") from exc
        return record_from_arrays(*arrays, source=str(path))
    return record_from_arrays(*_read_csv_columns(path, RECORD_KEYS), source=str(path))


def _read_csv_columns(path: Path, keys: tuple[str, ...]) -> list[np.ndarray]:
    """Read named float columns of a CSV with a header line; clear errors on any defect."""
    try:
        with path.open(newline="") as fh:
            reader = csv.reader(fh)
            try:
                header = [h.strip() for h in next(reader)]
            except StopIteration:
                raise RecordError(f"{path}: empty file") from None
            missing = [k for k in keys if k not in header]
            if missing:
                raise RecordError(
                    f"{path}: missing column(s) {', '.join(missing)}; header is {','.join(header)!r}, "
                    f"expected {','.join(keys)}"
                )
            idx = [header.index(k) for k in keys]
            rows = []
            for line_no, row in enumerate(reader, start=2):
                if not row or all(not c.strip() for c in row):
                    continue
                try:
                    rows.append([float(row[i]) for i in idx])
                except (ValueError, IndexError):
                    raise RecordError(f"{path}: line {line_no} is not {len(keys)} numbers: {','.join(row)[:80]!r}") from None
    except UnicodeDecodeError as exc:
        raise RecordError(f"{path}: not a text CSV file ({exc.reason})") from None
    if not rows:
        raise RecordError(f"{path}: no data rows")
    table = np.asarray(rows, dtype=float)
    return [table[:, j] for j in range(len(keys))]


def read_csv_columns(path: str | Path, keys: tuple[str, ...]) -> list[np.ndarray]:
    """Public form of the CSV column reader (used by other raw formats)."""
    return _read_csv_columns(Path(path), keys)


def write_record(path: str | Path, record: Record) -> Path:
    """Write a record as CSV (by default) or NPZ (when the name ends in .npz)."""
    path = Path(path)
    cols = np.column_stack([record.time_s, record.reference, record.response])
    if path.suffix.lower() == ".npz":
        np.savez(path, time_s=cols[:, 0], reference=cols[:, 1], response=cols[:, 2])
    else:
        np.savetxt(path, cols, delimiter=",", header=",".join(RECORD_KEYS), comments="", fmt="%.10g")
    return path
