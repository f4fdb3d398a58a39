"""Shot files: one HDF5 file per shot, raw data written atomically before any analysis.

Layout (format "hopkinson-shot", format_version 1)::

    /                      attrs: format, format_version, state ("raw" | "analysed" |
                           "analysis_failed"), uuid, utc_time (ISO 8601, UTC), operator,
                           accelerometer_model, accelerometer_serial, software_version,
                           pressure_bar, projectile, simulated (bool), and when known shot_id,
                           shot_index, campaign_id (the run folder's name), campaign_uuid
                           (the campaign's identity, rig.journal); raw_sha256 (of the raw channels,
                           rig.shotfile_integrity.raw_sha256: the lab's record keys a shot by it and
                           refuses a file whose channels no longer match); config_json, instruments_json,
                           sensors_json (with further sensors: role -> {"model", "serial"}
                           of each, e.g. response_2's) and (in simulation) truth_json: the
                           exact JSON text of those dicts;
                           NX_class = "NXroot", default = "entry" (NeXus: where a viewer's
                           default plot is)
    /meta/config           the configuration snapshot mirrored as groups/attributes/datasets
                           (for people browsing the file; config_json is the exact copy)
    /meta/instruments      attrs: instrument name -> identity string
    /truth                 simulation only: the simulated truth mirrored (truth_json is exact)
    /raw                   attrs: sample_interval_s, trigger_index, channels (the roles present)
    /raw/<role>            the digitizer's codes exactly as recorded, in their native type
                           (int8, uint8, int16, uint16 or float32), one per role present
                           ("doppler", "response", "doppler_quadrature", "response_2");
                           attrs: scale_v, offset_v (volts = codes * scale_v + offset_v; also as
                           CF's scale_factor/add_offset, so netCDF-aware readers unpack volts),
                           units = "V" (of the unpacked value), long_name, sample_interval_s,
                           trigger_index, and code_min/code_max (the format's full-scale codes)
                           when the digitizer gave them; chunked with the HDF5 fletcher32
                           checksum so a damaged file is detected on read; dimension 0 is
                           the scale /raw/time_s
    /raw/time_s            time from the trigger, s (float64; an HDF5 dimension scale,
                           compressed: a ramp costs little)
    /derived/record        the reduced two-channel record: datasets reference (m/s^2) and
                           response (units from the reduction: m/s^2 when scaled by gain and
                           sensitivity, else V), time_s (s, their dimension scale); attrs
                           sample_interval_s, start_time_s
    /derived/<name>        any other derived array (e.g. velocity_m_s), units from its name
    /analysis              attrs: status ("ok" | "failed"), error (when failed), utc_time,
                           software_version, results_json (the whole results dict as JSON
                           text: the exact round-trip); groups mirror the results dict
                           (nested dicts -> groups, numbers/strings -> attributes, numeric
                           lists -> datasets; anything else -> a "<key>_json" attribute);
                           version (1, 2, ...: each re-analysis adds one)
    /analyses/<version>    the earlier analyses, each kept as /analysis was when it was current
                           (`hopkinson analyse` re-runs today's method; nothing is replaced)
    /entry                 NeXus NXentry, default = "signals": what a generic viewer (HDFView,
                           silx, h5web) plots without being told
    /entry/signals         NXdata: signal "response", auxiliary_signals (the other roles),
                           axes "time_s": the channels in volts (float32, units "V") against
                           /raw/time_s (hard links to the same data)
    /entry/record          NXdata (once analysed): signal "response", auxiliary_signals
                           ["reference"], axes "time_s": hard links into /derived/record

Units are spelled one way everywhere: "V", "s", "m/s^2", "m/s", "Hz" (UDUNITS).

Writing (atomically, never replacing raw data) is rig/shotfile_writer.py's; verifying a file
against its checksums and its raw channels' SHA-256 is rig/shotfile_integrity.py's.
"""

from __future__ import annotations

import importlib.metadata
import json
import re
import uuid as uuid_module
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import h5py
import numpy as np

from hopkinson.analysis.errors import RecordError
from hopkinson.analysis.full_scale import full_scale_volts
from hopkinson.analysis.records import Record
from hopkinson.rig.events import utc_now_iso

FORMAT = "hopkinson-shot"
FORMAT_VERSION = 1
TMP_SUFFIX = ".tmp"  # hopkinson.fileio's temporaries (.<name>.h5.<random>.tmp): an unfinished write
PLAIN_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


class ShotFileError(RecordError):
    """A shot file that cannot be written or read; the message names the file."""


class RawChannel(NamedTuple):
    """One digitizer channel as recorded: volts = codes * scale_v + offset_v."""

    codes: np.ndarray  # native type: int8, uint8, int16, uint16 or float32
    scale_v: float
    offset_v: float
    code_range: tuple[float, float] | None = None  # the format's full-scale codes, when known

    @property
    def volts(self) -> np.ndarray:
        return self.codes.astype(np.float64) * self.scale_v + self.offset_v

    @property
    def full_scale_v(self) -> tuple[float, float] | None:
        """The digitizer's full scale in volts (low, high), from the format's full-scale codes;
        None when they are not known (a file written before they were stored)."""
        if self.code_range is None:
            return None
        return full_scale_volts(self.code_range, self.scale_v, self.offset_v)


@dataclass(frozen=True)
class RawShot:
    """The raw channels of one shot, all sampled together."""

    channels: dict[str, RawChannel]  # role -> (codes, scale_v, offset_v[, code_range])
    sample_interval_s: float
    trigger_index: int  # sample index of the trigger within each channel

    def volts(self, name: str) -> np.ndarray:
        """Channel `name` converted to volts."""
        return RawChannel(*self.channels[name]).volts

    def full_scale_v(self) -> dict[str, tuple[float, float]]:
        """role -> the digitizer's full scale in volts, for each channel whose full-scale codes
        are known: what the analysis judges clipping against (never the record's own extremes)."""
        scales = {role: RawChannel(*channel).full_scale_v for role, channel in self.channels.items()}
        return {role: scale for role, scale in scales.items() if scale is not None}

    @property
    def time_s(self) -> np.ndarray:
        """Sample times relative to the trigger, s."""
        n = len(next(iter(self.channels.values()))[0])
        return (np.arange(n) - self.trigger_index) * self.sample_interval_s


def software_version() -> str:
    """The installed version of the `hopkinson` distribution ("unknown" when not installed)."""
    try:
        return importlib.metadata.version("hopkinson")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class ShotMeta:
    """Who, what, when and with which set-up a shot was fired."""

    operator: str
    accelerometer_model: str
    accelerometer_serial: str
    pressure_bar: float
    projectile: int
    instruments: dict[str, str] = field(default_factory=dict)  # name -> identity (*IDN? ...)
    # further sensors' identities: role (e.g. "response_2") -> {"model", "serial"}
    sensor_identities: dict[str, dict[str, str]] = field(default_factory=dict)
    config: dict[str, Any] = field(default_factory=dict)  # full rig configuration snapshot
    shot_id: str | None = None
    shot_index: int | None = None
    campaign_id: str | None = None
    campaign_uuid: str | None = None  # the campaign's identity (its journal's), never its folder's name
    simulated_truth: dict[str, Any] | None = None  # simulation only
    uuid: str = field(default_factory=lambda: str(uuid_module.uuid4()))
    utc_time: str = field(default_factory=utc_now_iso)
    software_version: str = field(default_factory=software_version)


@dataclass(frozen=True)
class Shot:
    """A shot file read back: meta, raw channels, and the analysis when there is one."""

    path: Path
    meta: ShotMeta
    raw: RawShot | None  # None when read with load_raw=False
    state: str  # "raw", "analysed" or "analysis_failed"
    results: dict[str, Any] | None = None
    analysis_error: str | None = None
    record: Record | None = None
    derived: dict[str, np.ndarray] = field(default_factory=dict)
    # Every analysis stored in the file, oldest first (the last is the current one, /analysis):
    # version, utc_time, software_version, status ("ok" | "failed") and error.
    analyses: tuple[dict[str, Any], ...] = ()

    def volts(self, name: str) -> np.ndarray:
        """Raw channel `name` in volts."""
        if self.raw is None:
            raise ShotFileError(f"{self.path}: raw channels were not loaded")
        return self.raw.volts(name)


# ----------------------------------------------------------------------------- reading


def _sensor_identities(text: str) -> dict[str, dict[str, str]]:
    """sensors_json read back: role -> {"model", "serial"} (ValueError when not that shape)."""
    data = json.loads(text)
    if not isinstance(data, dict) or not all(
            isinstance(v, dict) and all(isinstance(x, str) for x in v.values()) for v in data.values()):
        raise ValueError("sensors_json is not role -> {model, serial}")
    return {str(role): {str(k): v for k, v in ident.items()} for role, ident in data.items()}



def open_shot(path: Path) -> h5py.File:
    """Open a shot file read-only, or raise ShotFileError naming the file and the problem."""
    if path.name.endswith(TMP_SUFFIX):
        raise ShotFileError(f"{path}: an unfinished temporary file (an interrupted write), not a shot")
    if not path.exists():
        raise ShotFileError(f"{path}: no such file")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        reason = str(exc).split("(", 1)[-1].rstrip(")") if "(" in str(exc) else str(exc)
        raise ShotFileError(f"{path}: not a readable HDF5 shot file (truncated or corrupt: {reason})") from None
    if f.attrs.get("format") != FORMAT:
        f.close()
        raise ShotFileError(f"{path}: an HDF5 file but not a hopkinson shot file (no format={FORMAT!r})")
    version = int(f.attrs.get("format_version", 0))
    if version > FORMAT_VERSION:
        f.close()
        raise ShotFileError(f"{path}: shot file format version {version} is newer than this software reads")
    return f


def read_shot_meta(path: str | Path) -> ShotMeta:
    """Only the meta of a shot file (cheap: the root attributes; no raw, derived or analysis data)."""
    path = Path(path)
    f = open_shot(path)
    try:
        with f:
            return _meta(f.attrs)
    except KeyError as exc:
        raise ShotFileError(f"{path}: damaged shot file: meta: missing {exc}") from None
    except (OSError, ValueError) as exc:
        raise ShotFileError(f"{path}: damaged shot file: meta cannot be read ({exc})") from None


def _meta(attrs: Any) -> ShotMeta:
    """The ShotMeta held in a shot file's root attributes."""
    return ShotMeta(
        operator=str(attrs["operator"]),
        accelerometer_model=str(attrs["accelerometer_model"]),
        accelerometer_serial=str(attrs["accelerometer_serial"]),
        pressure_bar=float(attrs["pressure_bar"]),
        projectile=int(attrs["projectile"]),
        instruments=json.loads(attrs["instruments_json"]),
        sensor_identities=_sensor_identities(attrs["sensors_json"]) if "sensors_json" in attrs else {},
        config=json.loads(attrs["config_json"]),
        shot_id=str(attrs["shot_id"]) if "shot_id" in attrs else None,
        shot_index=int(attrs["shot_index"]) if "shot_index" in attrs else None,
        campaign_id=str(attrs["campaign_id"]) if "campaign_id" in attrs else None,
        campaign_uuid=str(attrs["campaign_uuid"]) if "campaign_uuid" in attrs else None,
        simulated_truth=json.loads(attrs["truth_json"]) if "truth_json" in attrs else None,
        uuid=str(attrs["uuid"]),
        utc_time=str(attrs["utc_time"]),
        software_version=str(attrs["software_version"]),
    )


def read_shot(path: str | Path, load_raw: bool = True) -> Shot:
    """Read a shot file: meta, raw channels (int16 + scaling), analysis and record if present."""
    path = Path(path)
    f = open_shot(path)
    where = "meta"
    try:
        with f:
            meta = _meta(f.attrs)
            where = "/raw"
            raw_group = f["raw"]
            raw = None
            if load_raw:
                channels = {}
                for name in raw_group.attrs["channels"]:
                    where = f"/raw/{name}"
                    ds = raw_group[name]
                    code_range = ((float(ds.attrs["code_min"]), float(ds.attrs["code_max"]))
                                  if "code_min" in ds.attrs and "code_max" in ds.attrs else None)
                    channels[str(name)] = RawChannel(
                        ds[...], float(ds.attrs["scale_v"]), float(ds.attrs["offset_v"]), code_range
                    )
                raw = RawShot(
                    channels,
                    float(raw_group.attrs["sample_interval_s"]),
                    int(raw_group.attrs["trigger_index"]),
                )
            where = "/analysis"
            results = error = record = None
            analyses: list[dict[str, Any]] = []
            if PREVIOUS_ANALYSES in f:
                analyses = [_analysis_summary(group) for group in f[PREVIOUS_ANALYSES].values()]
            if "analysis" in f:
                analysis = f["analysis"]
                results = json.loads(analysis.attrs["results_json"])
                error = str(analysis.attrs["error"]) if "error" in analysis.attrs else None
                analyses.append(_analysis_summary(analysis))
            analyses.sort(key=lambda a: a["version"])
            where = "/derived"
            derived = {}
            if "derived" in f:
                for name, obj in f["derived"].items():
                    if name == "record":
                        record = Record(
                            float(obj.attrs["sample_interval_s"]),
                            obj["reference"][...],
                            obj["response"][...],
                            float(obj.attrs["start_time_s"]),
                        )
                    else:
                        derived[name] = obj[...]
            return Shot(path, meta, raw, str(f.attrs["state"]), results, error, record, derived, tuple(analyses))
    except KeyError as exc:
        raise ShotFileError(f"{path}: damaged shot file: {where}: missing {exc}") from None
    except (OSError, ValueError) as exc:
        raise ShotFileError(f"{path}: damaged shot file: {where} cannot be read ({exc})") from None


PREVIOUS_ANALYSES = "analyses"  # /analyses/<version>: the earlier analyses, each as /analysis was


def analysis_results(path: str | Path, version: int) -> dict[str, Any] | None:
    """The results dict of one analysis version of a shot file (None when there is no such
    version): the current /analysis or an earlier /analyses/<version>."""
    path = Path(path)
    with open_shot(path) as f:
        for name in ("analysis", f"{PREVIOUS_ANALYSES}/{version}"):
            if name in f and int(f[name].attrs.get("version", 1)) == version:
                try:
                    return json.loads(f[name].attrs["results_json"])
                except (KeyError, ValueError) as exc:
                    raise ShotFileError(f"{path}: damaged shot file: {name} cannot be read ({exc})") from None
    return None


def _analysis_summary(group: h5py.Group) -> dict[str, Any]:
    """An analysis group's version, time, software version, status and error."""
    a = group.attrs
    return {"version": int(a.get("version", 1)), "utc_time": str(a.get("utc_time", "")),
            "software_version": str(a.get("software_version", "")), "status": str(a.get("status", "")),
            "error": str(a["error"]) if "error" in a else None}


def sensor_response_name(role: str, unit: str) -> str:
    """The /derived name of a further sensor's record response (e.g. "response_2_m_s2"): it
    shares /derived/record's time axis and reference; the suffix states its unit."""
    return f"{role}_m_s2" if unit in ("m/s^2", "m/s2", "m/s²") else f"{role}_v"


def sensor_records(shot: Shot) -> dict[str, Record]:
    """role -> the record of each further sensor (the results' "sensors") whose response the
    shot file keeps in /derived, on /derived/record's time axis and reference."""
    record = shot.record
    out: dict[str, Record] = {}
    if record is None:
        return out
    for role in ((shot.results or {}).get("sensors") or {}):
        for unit in ("m/s^2", "V"):
            response = shot.derived.get(sensor_response_name(role, unit))
            if response is not None and response.shape == record.response.shape:
                out[role] = Record(record.sample_interval_s, record.reference, response, record.start_time_s)
    return out


