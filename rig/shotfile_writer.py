"""Writing shot files (the layout: rig/shotfile.py): the raw shot once, then each analysis.

Durability. Every write goes through hopkinson.fileio.atomic_write: the file is built under an
exclusively created temporary name beside the target (`.<name>.h5.<random>.tmp`, never
through a symlink), fsynced and renamed over the final name, and the folder fsynced; a crash
leaves either no file or a complete one under the final name, plus possibly a `*.tmp`
leftover that rig.run_folder removes on resume. `write_raw_shot` never replaces an existing
shot file. `add_analysis` never opens the shot file for writing: HDF5 has no journal, so an
append that dies half-way can damage the file's metadata and with it the raw data. Instead it
copies the file byte for byte into memory, replaces /derived, /analysis and /entry/record in
the copy (every reference inside the file, such as the dimension scales, stays valid in a
byte copy) and writes it to the temporary, renamed over the old one. Every HDF5 file is built
in memory and written with plain os.write, so a full disk or a quota is one OSError (a
ShotFileError naming the file), never HDF5 failing inside its own clean-up. Until that rename the old file is untouched; after
it the new file is complete. The cost is one copy of the file per analysis (tens of ms for
2 × 10 M samples).
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import math
import uuid as uuid_module
from collections.abc import Callable
from datetime import date, datetime, time
from enum import Enum
from pathlib import Path, PurePath
from typing import Any

import h5py
import numpy as np

from hopkinson.analysis.records import Record
from hopkinson.fileio import UnsafeOutputError, atomic_write
from hopkinson.rig.events import utc_now_iso
from hopkinson.rig.shotfile import (
    FORMAT,
    FORMAT_VERSION,
    PLAIN_NAME_RE,
    PREVIOUS_ANALYSES,
    RawChannel,
    RawShot,
    ShotFileError,
    ShotMeta,
    open_shot,
    software_version,
)
from hopkinson.rig.shotfile_integrity import raw_sha256

REQUIRED_CHANNELS = ("doppler", "response")
CODE_DTYPES = tuple(np.dtype(t) for t in ("int8", "uint8", "int16", "uint16", "float32"))  # as digitizers send them
TIME_NAME = "time_s"
ROLE_NAMES = {  # long names for viewers
    "doppler": "photomultiplier (Doppler beat)",
    "doppler_quadrature": "photomultiplier, quadrature",
    "response": "accelerometer response (amplifier output)",
    "response_2": "second sensor (amplifier output)",
}
UNIT_SUFFIXES = (("_m_s2", "m/s^2"), ("_m_s", "m/s"), ("_hz", "Hz"), ("_s", "s"), ("_v", "V"), ("_m", "m"),
                 ("_bar", "bar"), ("_mbar", "mbar"))
_CHUNK_SAMPLES = 1 << 20  # 2 MiB chunks of int16: checksummed without slowing the write
CHECKSUMMED: dict[str, Any] = {"fletcher32": True}  # every dataset: a flipped byte fails its read


def write_raw_shot(path: str | Path, raw: RawShot, meta: ShotMeta) -> Path:
    """Write a new shot file atomically (tmp, flush, fsync, rename); never overwrites one."""
    path = Path(path)
    if path.exists():
        raise ShotFileError(f"{path}: a shot file already exists under this name; not overwritten")
    channels = _checked_channels(path, raw)
    _check_meta(path, meta)
    texts = {
        "config_json": _dumps(path, "config", meta.config),
        "instruments_json": _dumps(path, "instruments", meta.instruments),
    }
    if meta.sensor_identities:
        texts["sensors_json"] = _dumps(path, "further sensors' identities", meta.sensor_identities)
    if meta.simulated_truth is not None:
        texts["truth_json"] = _dumps(path, "simulated truth", meta.simulated_truth)

    def build(f: h5py.File) -> None:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["state"] = "raw"
        for key in ("uuid", "utc_time", "operator", "accelerometer_model",
                    "accelerometer_serial", "software_version"):
            f.attrs[key] = str(getattr(meta, key))
        f.attrs["pressure_bar"] = float(meta.pressure_bar)
        f.attrs["projectile"] = int(meta.projectile)
        f.attrs["simulated"] = meta.simulated_truth is not None
        f.attrs["raw_sha256"] = raw_sha256(RawShot(channels, raw.sample_interval_s, raw.trigger_index))
        for key in ("shot_id", "campaign_id", "campaign_uuid"):
            if getattr(meta, key) is not None:
                f.attrs[key] = str(getattr(meta, key))
        if meta.shot_index is not None:
            f.attrs["shot_index"] = int(meta.shot_index)
        for key, text in texts.items():
            f.attrs[key] = text
        meta_group = f.create_group("meta")
        _mirror(meta_group.create_group("config"), meta.config)
        instruments = meta_group.create_group("instruments")
        for name, identity in meta.instruments.items():
            instruments.attrs[_h5_name(str(name))] = str(identity)
        if meta.simulated_truth is not None:
            _mirror(f.create_group("truth"), meta.simulated_truth)
        raw_group = f.create_group("raw")
        raw_group.attrs["sample_interval_s"] = float(raw.sample_interval_s)
        raw_group.attrs["trigger_index"] = int(raw.trigger_index)
        raw_group.attrs["channels"] = list(channels)
        n = next(iter(channels.values())).codes.size
        time_s = _time_scale(raw_group, (np.arange(n) - raw.trigger_index) * raw.sample_interval_s,
                             "time from the trigger")
        for name, channel in channels.items():
            codes = channel.codes
            ds = raw_group.create_dataset(
                name, data=codes, chunks=(min(codes.size, _CHUNK_SAMPLES),), fletcher32=True
            )
            ds.attrs["scale_v"] = channel.scale_v
            ds.attrs["offset_v"] = channel.offset_v
            ds.attrs["scale_factor"] = channel.scale_v  # CF convention: unpacked = codes * scale_factor + add_offset
            ds.attrs["add_offset"] = channel.offset_v
            ds.attrs["sample_interval_s"] = float(raw.sample_interval_s)
            ds.attrs["trigger_index"] = int(raw.trigger_index)
            ds.attrs["units"] = "V"
            ds.attrs["long_name"] = f"{ROLE_NAMES.get(name, name)}: digitizer codes (volts = codes · scale_v + offset_v)"
            if channel.code_range is not None:
                ds.attrs["code_min"], ds.attrs["code_max"] = channel.code_range
            ds.dims[0].attach_scale(time_s)
        _nexus_signals(f, channels, time_s)

    _atomic_write(path, build)
    return path



def add_analysis(
    path: str | Path,
    results: dict[str, Any],
    record: Record | None = None,
    error: str | None = None,
    derived: dict[str, np.ndarray] | None = None,
    response_units: str | None = None,
) -> Path:
    """Store analysis results (and the reduced record) in an existing shot file, atomically.

    With `error` the analysis is recorded as failed (state "analysis_failed"); `results` may
    then hold whatever was computed before the failure. A second call keeps the previous
    /analysis as /analyses/<its version> and writes the new one (version + 1) as /analysis;
    /derived (recomputed from the raw data) is replaced. The raw data is copied, never rewritten in place (module doc).
    response_units: the record's response unit (default: the reduction's `response_unit` in
    the results, else "1").
    """
    path = Path(path)
    open_shot(path).close()  # a readable shot file, or a clear error before anything is written
    results_json = _dumps(path, "analysis results", results)
    derived_arrays = {}
    for name, values in (derived or {}).items():
        arr = np.asarray(values)
        if arr.dtype.kind not in "biuf" or name == "record" or not PLAIN_NAME_RE.match(name):
            raise ShotFileError(f"{path}: derived '{name}' must be a numeric array with a plain name")
        derived_arrays[name] = arr
    if record is not None and not isinstance(record, Record):
        raise ShotFileError(f"{path}: record must be an analysis.records.Record")

    units = response_units or ((results.get("reduction") or {}).get("response_unit") if isinstance(results, dict)
                               else None) or "1"

    def build(dst: h5py.File) -> None:
        # dst is a byte copy of the shot file (module doc): the current analysis becomes an earlier
        # version under /analyses/<version> (its results kept, never replaced); the reduced record
        # in /derived is replaced (it is recomputed from the raw data by any re-analysis).
        version = 1
        if "analysis" in dst:
            previous = int(dst["analysis"].attrs.get("version", 1))
            dst.require_group(PREVIOUS_ANALYSES)
            dst.move("analysis", f"{PREVIOUS_ANALYSES}/{previous}")
            version = previous + 1
        if "derived" in dst:
            del dst["derived"]
        if "entry" in dst and "record" in dst["entry"]:
            del dst["entry/record"]
        dst.attrs["state"] = "analysis_failed" if error is not None else "analysed"
        derived_group = dst.create_group("derived")
        if record is not None:
            rec = derived_group.create_group("record")
            rec.attrs["sample_interval_s"] = float(record.sample_interval_s)
            rec.attrs["start_time_s"] = float(record.start_time_s)
            time_s = _time_scale(rec, record.time_s, "time")
            for key, values, unit, long_name in (
                ("reference", record.reference, "m/s^2", "reference acceleration (laser interferometer)"),
                ("response", record.response, units, "accelerometer response"),
            ):
                ds = rec.create_dataset(key, data=np.asarray(values, dtype=float), **CHECKSUMMED)
                ds.attrs["units"] = unit
                ds.attrs["long_name"] = f"{long_name} ({unit})"
                ds.dims[0].attach_scale(time_s)
            _nexus_record(dst, rec)
        for name, arr in derived_arrays.items():
            ds = derived_group.create_dataset(name, data=arr, **CHECKSUMMED)
            ds.attrs["units"] = units_of_name(name)
        analysis = dst.create_group("analysis")
        analysis.attrs["version"] = version
        analysis.attrs["status"] = "failed" if error is not None else "ok"
        if error is not None:
            analysis.attrs["error"] = str(error)
        analysis.attrs["utc_time"] = utc_now_iso()
        analysis.attrs["software_version"] = software_version()
        analysis.attrs["results_json"] = results_json
        analysis.attrs["results_sha256"] = hashlib.sha256(results_json.encode("utf-8")).hexdigest()
        _mirror(analysis, results)

    _atomic_write(path, build, seed=path)
    return path


def units_of_name(name: str) -> str:
    """The unit a name's suffix states (`velocity_m_s` -> "m/s"); "1" (a plain number) without one."""
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return "1"


def _time_scale(group: h5py.Group, time_s: np.ndarray, long_name: str) -> h5py.Dataset:
    """A time axis (s) as an HDF5 dimension scale; compressed (a ramp shrinks ~25×)."""
    n = int(np.size(time_s))
    options = dict(chunks=(min(n, _CHUNK_SAMPLES),), compression="gzip", compression_opts=1, shuffle=True) \
        if n > 4096 else {}
    options["fletcher32"] = True
    ds = group.create_dataset(TIME_NAME, data=np.asarray(time_s, dtype=np.float64), **options)
    ds.attrs["units"] = "s"
    ds.attrs["long_name"] = f"{long_name} (s)"
    ds.make_scale(long_name)
    return ds


def _nexus_signals(f: h5py.File, channels: dict[str, RawChannel], time_s: h5py.Dataset) -> None:
    """/entry/signals: every channel in volts against time, the file's default plot (NeXus NXdata)."""
    f.attrs["NX_class"] = "NXroot"
    f.attrs["default"] = "entry"
    entry = f.create_group("entry")
    entry.attrs["NX_class"] = "NXentry"
    entry.attrs["default"] = "signals"
    data = entry.create_group("signals")
    data.attrs["NX_class"] = "NXdata"
    data.attrs["signal"] = "response"
    data.attrs["auxiliary_signals"] = [name for name in channels if name != "response"]
    data.attrs["axes"] = [TIME_NAME]
    data.attrs[f"{TIME_NAME}_indices"] = 0
    data[TIME_NAME] = time_s  # a hard link: one time axis in the file
    for name, channel in channels.items():
        volts = (channel.codes.astype(np.float64) * channel.scale_v + channel.offset_v).astype(np.float32)
        ds = data.create_dataset(name, data=volts, chunks=(min(volts.size, _CHUNK_SAMPLES),), fletcher32=True)
        ds.attrs["units"] = "V"
        ds.attrs["long_name"] = f"{ROLE_NAMES.get(name, name)} (V)"
        ds.dims[0].attach_scale(time_s)


def _nexus_record(f: h5py.File, record_group: h5py.Group) -> None:
    """/entry/record: the analysed two-channel record (NeXus NXdata), linked to /derived/record."""
    if "entry" not in f:  # a shot file written before the NeXus default existed
        return
    data = f["entry"].create_group("record")
    data.attrs["NX_class"] = "NXdata"
    data.attrs["signal"] = "response"
    data.attrs["auxiliary_signals"] = ["reference"]
    data.attrs["axes"] = [TIME_NAME]
    data.attrs[f"{TIME_NAME}_indices"] = 0
    for name in ("response", "reference", TIME_NAME):
        data[name] = record_group[name]


def _atomic_write(final: Path, build: Callable[[h5py.File], None], seed: Path | None = None) -> None:
    """Build an HDF5 file and publish it as `final` through hopkinson.fileio.atomic_write (an
    exclusive temporary beside it, fsynced, renamed, the folder fsynced): new, or a byte copy of
    `seed` opened for update.

    The file is built in memory and reaches the disk through plain os.write: HDF5 writing to a
    file that fills up (a full disk, a quota) fails inside its own clean-up, where h5py can only
    print the error while the process goes on or crashes (docs/decisions/0007). In memory nothing can fail that way; the disk's failure is then an OSError of
    one write, and atomic_write removes the temporary."""
    try:
        image = io.BytesIO(seed.read_bytes() if seed is not None else b"")
    except OSError as exc:
        raise ShotFileError(f"{seed}: could not be read ({exc})") from exc
    with h5py.File(image, "r+" if seed is not None else "w", track_order=True) as f:
        build(f)
    try:
        atomic_write(final, image.getbuffer())
    except UnsafeOutputError as exc:
        raise ShotFileError(str(exc)) from None
    except OSError as exc:
        raise ShotFileError(f"{final}: could not be written ({exc})") from exc


def _checked_channels(path: Path, raw: RawShot) -> dict[str, RawChannel]:
    missing = [c for c in REQUIRED_CHANNELS if c not in raw.channels]
    if missing:
        raise ShotFileError(f"{path}: raw shot lacks channel(s) {', '.join(missing)}")
    if not (math.isfinite(raw.sample_interval_s) and raw.sample_interval_s > 0):
        raise ShotFileError(f"{path}: sample_interval_s must be > 0 (got {raw.sample_interval_s})")
    out: dict[str, RawChannel] = {}
    lengths = set()
    for name, channel in raw.channels.items():
        if not PLAIN_NAME_RE.match(name) or name == TIME_NAME:
            raise ShotFileError(f"{path}: channel name {name!r} is not a plain name")
        try:
            codes, scale_v, offset_v, *rest = channel
            code_range = rest[0] if rest else None
        except (TypeError, ValueError):
            raise ShotFileError(f"{path}: channel '{name}' must be (codes, scale_v, offset_v)") from None
        codes = np.asarray(codes)
        if codes.ndim != 1 or codes.size == 0:
            raise ShotFileError(f"{path}: channel '{name}' must be a non-empty 1-D array")
        if codes.dtype not in CODE_DTYPES:
            if codes.dtype.kind not in "iu" or codes.min() < -32768 or codes.max() > 32767:
                raise ShotFileError(
                    f"{path}: channel '{name}' must hold int16 codes (or int8, uint8, uint16, float32) as "
                    f"recorded, or integers that fit int16 (got {codes.dtype})"
                )
            codes = codes.astype(np.int16)
        if not (math.isfinite(scale_v) and scale_v != 0 and math.isfinite(offset_v)):
            raise ShotFileError(f"{path}: channel '{name}' scale_v/offset_v must be finite, scale non-zero")
        if code_range is not None:
            lo, hi = (float(c) for c in code_range)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ShotFileError(f"{path}: channel '{name}' code_range must be two finite codes, low < high")
            code_range = (lo, hi)
        lengths.add(codes.size)
        out[name] = RawChannel(codes, float(scale_v), float(offset_v), code_range)
    if len(lengths) != 1:
        raise ShotFileError(f"{path}: raw channels have different lengths {sorted(lengths)}")
    n = lengths.pop()
    if not 0 <= raw.trigger_index < n:
        raise ShotFileError(f"{path}: trigger_index {raw.trigger_index} outside 0..{n - 1}")
    return out


def _check_meta(path: Path, meta: ShotMeta) -> None:
    try:
        uuid_module.UUID(meta.uuid)
    except (ValueError, AttributeError, TypeError):
        raise ShotFileError(f"{path}: meta uuid {meta.uuid!r} is not a UUID") from None
    try:
        stamp = datetime.fromisoformat(meta.utc_time)
    except (ValueError, TypeError):
        raise ShotFileError(f"{path}: meta utc_time {meta.utc_time!r} is not ISO 8601") from None
    if stamp.utcoffset() is None or stamp.utcoffset().total_seconds() != 0:
        raise ShotFileError(f"{path}: meta utc_time {meta.utc_time!r} must be UTC (end in Z or +00:00)")
    if not (isinstance(meta.pressure_bar, int | float) and math.isfinite(meta.pressure_bar)):
        raise ShotFileError(f"{path}: meta pressure_bar must be a finite number")
    if isinstance(meta.projectile, bool) or not isinstance(meta.projectile, int):
        raise ShotFileError(f"{path}: meta projectile must be an integer")
    for key in ("instruments", "config"):
        if not isinstance(getattr(meta, key), dict):
            raise ShotFileError(f"{path}: meta {key} must be a dict")


def _json_default(obj: Any) -> Any:
    """JSON form of what a config snapshot or results may hold besides JSON types.

    Arrays become lists, dataclasses (typed config sections) dicts, paths and TOML dates
    text, enums their value; read back, they are those JSON forms.
    """
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    if isinstance(obj, datetime | date | time):
        return obj.isoformat()
    if isinstance(obj, PurePath):
        return str(obj)
    if isinstance(obj, Enum):
        return obj.value
    if isinstance(obj, set | frozenset):
        return sorted(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON-ready")


def _dumps(path: Path, what: str, obj: Any) -> str:
    # NaN/Infinity are allowed (Python's json reads them back); results may hold a NaN.
    try:
        return json.dumps(obj, default=_json_default, allow_nan=True)
    except (TypeError, ValueError) as exc:
        raise ShotFileError(f"{path}: {what} cannot be stored as JSON ({exc})") from None


def _h5_name(key: str) -> str:
    """An HDF5-safe link name for a dict key ('/' separates paths; '.' is reserved)."""
    name = key.replace("/", "_")
    return "_" if name in ("", ".") else name


def _mirror(group: h5py.Group, obj: dict[str, Any]) -> None:
    """Mirror a JSON-ready dict into a group for people browsing the file (not the exact copy)."""
    for key, value in obj.items():
        name = _h5_name(str(key))
        if name in group or name in group.attrs:
            continue  # two keys that map to one name: the JSON copy keeps both
        if isinstance(value, dict):
            _mirror(group.create_group(name), value)
        elif value is None:
            continue
        elif isinstance(value, str | bool | int | float | np.generic):
            group.attrs[name] = value
        else:
            arr = _numeric_array(value)
            if arr is not None:
                ds = group.create_dataset(name, data=arr, **CHECKSUMMED)
                if units_of_name(name) != "1":
                    ds.attrs["units"] = units_of_name(name)
            elif isinstance(value, list | tuple) and value and all(isinstance(v, str) for v in value):
                group.attrs[name] = list(value)
            else:
                group.attrs[name + "_json"] = json.dumps(value, default=_json_default)


def _numeric_array(value: Any) -> np.ndarray | None:
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        return None
    if arr.dtype.kind in "biuf" and arr.size > 0:
        return arr
    return None
