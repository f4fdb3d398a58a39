"""Two-channel records (the interchange format): CSV or NPZ with time_s, reference, response.

The reference is acceleration in m/s²; the response is in any unit (V, m/s², counts).
Every reader validates what it loads and names the file and the problem when it cannot.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hopkinson.analysis.errors import RecordError

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


def validated_columns(
    columns: list[np.ndarray], keys: tuple[str, ...], source: str, min_samples: int = 16
) -> tuple[float, list[np.ndarray]]:
    """Check columns (the first is time_s) and return (sample interval s, float columns).

    Every column finite and of one length, at least `min_samples`, time increasing with a
    uniform step (within 0.1 %); `source` names the data in the errors.
    """
    cols = []
    for key, col in zip(keys, columns, strict=True):
        arr = np.asarray(col, dtype=float).ravel()
        if not np.all(np.isfinite(arr)):
            bad = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise RecordError(f"{source}: column '{key}' has a NaN or infinite value at row {bad}")
        cols.append(arr)
    n = cols[0].size
    if any(c.size != n for c in cols):
        raise RecordError(f"{source}: columns have different lengths")
    if n < min_samples:
        raise RecordError(f"{source}: only {n} samples; at least {min_samples} are needed")
    dt = np.diff(cols[0])
    step = float(np.median(dt))
    if not step > 0:
        raise RecordError(f"{source}: time_s is not increasing")
    if np.max(np.abs(dt - step)) > 1e-3 * step:
        raise RecordError(f"{source}: time_s is not uniformly sampled (step varies by more than 0.1 %)")
    return step, cols


def record_from_arrays(
    time_s: np.ndarray, reference: np.ndarray, response: np.ndarray, source: str = "record"
) -> Record:
    """Validate three columns and build a Record; `source` names the data in errors."""
    step, (t, ref, resp) = validated_columns([time_s, reference, response], RECORD_KEYS, source)
    return Record(step, ref, resp, float(t[0]))


def read_columns(path: str | Path, keys: tuple[str, ...], what: str = "record") -> list[np.ndarray]:
    """Named float columns of an NPZ (by key) or a CSV with a header line (any other suffix).

    `what` names the kind of file in errors ("an NPZ record needs time_s, ...").
    """
    path = Path(path)
    if not path.exists():
        raise RecordError(f"{path}: no such file")
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as data:
                missing = [k for k in keys if k not in data.files]
                if missing:
                    raise RecordError(f"{path}: missing key(s) {', '.join(missing)}; an NPZ {what} needs "
                                      f"{', '.join(keys)}")
                return [np.asarray(data[k], dtype=float).ravel() for k in keys]
        except RecordError:
            raise
        except (OSError, ValueError) as exc:
            raise RecordError(f"{path}: not a readable NPZ file ({exc})") from None
    return _read_csv_columns(path, keys, what)


def read_record(path: str | Path) -> Record:
    """Read a CSV (header time_s,reference,response) or NPZ (same keys) record."""
    return record_from_arrays(*read_columns(path, RECORD_KEYS), source=str(path))


def _read_csv_columns(path: Path, keys: tuple[str, ...], what: str) -> list[np.ndarray]:
    """Read named float columns of a CSV with a header line (numpy's C parser: fast for 10⁷ rows)."""
    try:
        with path.open(newline="") as fh:
            header = next(csv.reader(fh), None)
    except UnicodeDecodeError as exc:
        raise RecordError(f"{path}: not a text CSV file ({exc.reason})") from None
    if header is None:
        raise RecordError(f"{path}: empty file")
    names = [h.strip() for h in header]
    missing = [k for k in keys if k not in names]
    if missing:
        raise RecordError(
            f"{path}: missing column(s) {', '.join(missing)}; header is {','.join(names)!r}, "
            f"a CSV {what} needs {','.join(keys)}"
        )
    try:
        table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, usecols=[names.index(k) for k in keys])
    except (ValueError, UnicodeDecodeError) as exc:
        raise RecordError(f"{path}: not a numeric table below the header ({exc})") from None
    if table.shape[0] == 0:
        raise RecordError(f"{path}: no data rows")
    return [table[:, j].copy() for j in range(len(keys))]


def write_record(path: str | Path, record: Record) -> Path:
    """Write a record as CSV (by default) or NPZ (when the name ends in .npz)."""
    path = Path(path)
    cols = np.column_stack([record.time_s, record.reference, record.response])
    if path.suffix.lower() == ".npz":
        np.savez(path, time_s=cols[:, 0], reference=cols[:, 1], response=cols[:, 2])
    else:
        np.savetxt(path, cols, delimiter=",", header=",".join(RECORD_KEYS), comments="", fmt="%.10g")
    return path
