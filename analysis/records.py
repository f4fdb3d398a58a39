"""Two-channel records (the interchange format): CSV or NPZ with time_s, reference, response.

The reference is acceleration in m/s²; the response is in any unit (V, m/s², counts). Units
travel with the file: a CSV header names them in brackets, `time_s,reference [m/s^2],response [V]`
(a header without units, `time_s,reference,response`, still reads); an NPZ holds them as
`<key>_unit` strings beside the arrays. Units are spelled as in the shot files ("m/s^2", "V", "s").

Every reader validates what it loads and names the file and the problem in one line when it
cannot: a missing file, a folder, a device or pipe (/dev/zero), a header line over
MAX_HEADER_BYTES, a row with more or fewer fields than the header, a non-numeric, NaN,
infinite or absurd (|x| > MAX_ABS_VALUE) value. Writers go through hopkinson.fileio (atomic).
"""

from __future__ import annotations

import csv
import re
import stat
import warnings
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hopkinson.analysis.errors import RecordError
from hopkinson.fileio import atomic_open

RECORD_KEYS = ("time_s", "reference", "response")
MAX_HEADER_BYTES = 64 * 1024  # a record's header is a few names; more is not a record CSV
MAX_ABS_VALUE = 1e30  # beyond any physical value in any unit; squares and sums stay finite
# A shock record's sample interval: 1 GS/s .. 1 kS/s (a time column in µs or ms read as seconds
# falls outside, and would make an analysis of a resampled record ask for petabytes).
MIN_STEP_S, MAX_STEP_S = 1e-9, 1e-3
_HEADER_CELL = re.compile(r"^\s*(?P<name>[^\[\]]*?)\s*(?:\[(?P<unit>[^\[\]]*)\])?\s*$")
_COLUMNS_CHANGED = re.compile(r"number of columns changed from (\d+) to (\d+) at row (\d+)")


@dataclass(frozen=True)
class Record:
    """A uniformly sampled two-channel record."""

    sample_interval_s: float
    reference: np.ndarray  # reference acceleration, m/s²
    response: np.ndarray  # accelerometer response (any unit)
    start_time_s: float = 0.0
    response_unit: str | None = None  # "V", "m/s^2", ... when known (a file without units: None)

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
        if arr.size and np.max(np.abs(arr)) > MAX_ABS_VALUE:
            bad = int(np.flatnonzero(np.abs(arr) > MAX_ABS_VALUE)[0])
            raise RecordError(f"{source}: column '{key}' has the value {arr[bad]:g} at row {bad}, beyond any "
                              f"physical value (|x| > {MAX_ABS_VALUE:g})")
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
    if not MIN_STEP_S <= step <= MAX_STEP_S:
        raise RecordError(f"{source}: time_s steps by {step:g} s, implausible for a shock record (expected "
                          f"{MIN_STEP_S:g} .. {MAX_STEP_S:g} s): is the time column in seconds?")
    if np.max(np.abs(dt - step)) > 1e-3 * step:
        raise RecordError(f"{source}: time_s is not uniformly sampled (step varies by more than 0.1 %)")
    return step, cols


def record_from_arrays(
    time_s: np.ndarray, reference: np.ndarray, response: np.ndarray, source: str = "record",
    response_unit: str | None = None,
) -> Record:
    """Validate three columns and build a Record; `source` names the data in errors."""
    step, (t, ref, resp) = validated_columns([time_s, reference, response], RECORD_KEYS, source)
    return Record(step, ref, resp, float(t[0]), response_unit)


@dataclass(frozen=True)
class Table:
    """Named float columns read from a file, with the unit of each column when the file gives one."""

    columns: list[np.ndarray]
    units: dict[str, str]  # key -> unit, only for the columns whose unit the file names


def read_columns(path: str | Path, keys: tuple[str, ...], what: str = "record") -> list[np.ndarray]:
    """Named float columns of an NPZ (by key) or a CSV with a header line (any other suffix).

    `what` names the kind of file in errors ("an NPZ record needs time_s, ...").
    """
    return read_table(path, keys, what).columns


def read_table(path: str | Path, keys: tuple[str, ...], what: str = "record") -> Table:
    """Like `read_columns`, with the units the file names (CSV header brackets, NPZ `<key>_unit`)."""
    path = Path(path)
    _check_regular_file(path, what)
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as data:
                missing = [k for k in keys if k not in data.files]
                if missing:
                    raise RecordError(f"{path}: missing key(s) {', '.join(missing)}; an NPZ {what} needs "
                                      f"{', '.join(keys)}")
                units = {k: str(data[f"{k}_unit"]) for k in keys if f"{k}_unit" in data.files}
                return Table([np.asarray(data[k], dtype=float).ravel() for k in keys], units)
        except RecordError:
            raise
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise RecordError(f"{path}: not a readable NPZ file ({exc})") from None
    return _read_csv_table(path, keys, what)


def column_names(path: str | Path, what: str = "record") -> list[str]:
    """The column names a table file holds: an NPZ's keys, a CSV header's names (units
    dropped); for optional columns. RecordError when the file cannot be read."""
    path = Path(path)
    _check_regular_file(path, what)
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as data:
                return list(data.files)
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise RecordError(f"{path}: not a readable NPZ file ({exc})") from None
    return [parse_header_cell(h)[0] for h in _read_header(path)]


def _check_regular_file(path: Path, what: str) -> None:
    """A readable regular file, or RecordError naming what it is instead."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise RecordError(f"{path}: no such file") from None
    except OSError as exc:
        raise RecordError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(mode):
        raise RecordError(f"{path}: a folder, not a {what} file")
    if not stat.S_ISREG(mode):
        raise RecordError(f"{path}: not a regular file (a device, pipe or socket), not a {what} file")


def read_record(path: str | Path) -> Record:
    """Read a CSV (header time_s,reference,response, units optional) or NPZ (same keys) record."""
    table = read_table(path, RECORD_KEYS)
    reference_unit = table.units.get("reference")
    if reference_unit is not None and reference_unit not in ("m/s^2", "m/s2", "m/s²"):
        raise RecordError(f"{path}: the reference must be acceleration in m/s^2 (the header says {reference_unit!r})")
    return record_from_arrays(*table.columns, source=str(path), response_unit=table.units.get("response"))


def parse_header_cell(cell: str) -> tuple[str, str | None]:
    """`reference [m/s^2]` -> ("reference", "m/s^2"); `reference` -> ("reference", None)."""
    m = _HEADER_CELL.match(cell)
    if m is None:
        return cell.strip(), None
    unit = m.group("unit")
    return m.group("name"), unit.strip() if unit is not None and unit.strip() else None


def _read_header(path: Path) -> list[str]:
    """The first line's cells, read with a size limit (a header is never megabytes long)."""
    try:
        with path.open("rb") as fh:
            line = fh.readline(MAX_HEADER_BYTES + 1)
    except OSError as exc:
        raise RecordError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if not line:
        raise RecordError(f"{path}: empty file")
    if len(line) > MAX_HEADER_BYTES:
        raise RecordError(f"{path}: the header line is longer than {MAX_HEADER_BYTES // 1024} KiB: not a record CSV")
    try:
        text = line.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise RecordError(f"{path}: not a text CSV file ({exc.reason})") from None
    return next(csv.reader([text.rstrip("\r\n")]), [])


def _read_csv_table(path: Path, keys: tuple[str, ...], what: str) -> Table:
    """Read named float columns of a CSV with a header line (numpy's C parser: fast for 10⁷ rows).

    Every row must have as many fields as the header names (an extra or a missing field is an
    error naming the line)."""
    header = _read_header(path)
    parsed = [parse_header_cell(h) for h in header]
    names = [name for name, _unit in parsed]
    missing = [k for k in keys if k not in names]
    if missing:
        raise RecordError(
            f"{path}: missing column(s) {', '.join(missing)}; header is {','.join(h.strip() for h in header)!r}, "
            f"a CSV {what} needs {','.join(keys)}"
        )
    try:
        with warnings.catch_warnings():  # a header-only file: numpy warns, the check below says it
            warnings.simplefilter("ignore")
            table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, encoding="utf-8")
    except ValueError as exc:
        changed = _COLUMNS_CHANGED.search(str(exc))
        if changed:
            before, after, row = (int(g) for g in changed.groups())
            raise RecordError(f"{path}: line {row + 1} has {after} fields where the lines above have {before} "
                              f"(the header names {len(names)})") from None
        raise RecordError(f"{path}: not a numeric table below the header ({exc})") from None
    except UnicodeDecodeError as exc:
        raise RecordError(f"{path}: not a text CSV file ({exc.reason})") from None
    if table.shape[0] == 0:
        raise RecordError(f"{path}: no data rows")
    if table.shape[1] != len(names):
        raise RecordError(f"{path}: the rows have {table.shape[1]} fields but the header names {len(names)} "
                          f"({','.join(names)})")
    units = {name: unit for name, unit in parsed if unit is not None and name in keys}
    return Table([table[:, names.index(k)].copy() for k in keys], units)


def header_cell(key: str, unit: str | None) -> str:
    """`reference [m/s^2]`, or the bare key without a unit (time_s carries its unit in its name)."""
    return f"{key} [{unit}]" if unit and not key.endswith("_s") else key


def write_record(path: str | Path, record: Record) -> Path:
    """Write a record as CSV (by default) or NPZ (when the name ends in .npz), atomically, with
    its units: the reference in m/s^2, the response in `record.response_unit` when known."""
    path = Path(path)
    cols = np.column_stack([record.time_s, record.reference, record.response])
    units = {"time_s": "s", "reference": "m/s^2"}
    if record.response_unit:
        units["response"] = record.response_unit
    if path.suffix.lower() == ".npz":
        with atomic_open(path, "wb") as fh:
            np.savez(fh, time_s=cols[:, 0], reference=cols[:, 1], response=cols[:, 2],
                     **{f"{k}_unit": np.array(u) for k, u in units.items()})
    else:
        header = ",".join(header_cell(k, units.get(k)) for k in RECORD_KEYS)
        with atomic_open(path, "w", newline="") as fh:
            np.savetxt(fh, cols, delimiter=",", header=header, comments="", fmt="%.10g")
    return path
