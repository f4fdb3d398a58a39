"""Campaign plans: a TOML file listing the shots to fire, validated and expanded on load.

Example (config/campaigns/example.toml is the documented one)::

    name = "ayz3-sn0001"              # campaign name (run folders are named after it)
    operator = "A. Technician"
    description = "..."               # optional
    authorise_firing = false          # true: the plan itself authorises FIRE for its shots

    [accelerometer]
    model = "AYZ-3"
    serial = "SN0001"
    sensitivity_v_per_m_s2 = 2.0e-7   # optional nominal sensitivity (amplifier output)
    transverse_sensitivity_rel = 0.05 # optional: its stated (datasheet) transverse sensitivity (issue 40; default 5 %)
    sine_calibration = "sine.csv"     # optional: the sensor's sine calibration (frequency_hz,
                                      # magnitude,phase_deg[,u_magnitude_rel,u_phase_deg]; relative to
                                      # the plan's folder); every shot's model is fitted to the
                                      # record and to it together (analysis.sine_joint), and the
                                      # report compares the model with it

    [accelerometer_2]                 # optional: a second accelerometer recorded on the rig's
    model = "AYZ-3"                   # response_2 channel (its gain and nominal sensitivity:
    serial = "SN0002"                 # the rig config's [analysis] amp_gain_2, sensitivity_2_...)

    [defaults]                        # every key optional; per-shot keys override
    pressure_bar = 2.0
    projectile = 3                    # 1, 2 or 3 (No. 3 gives the shortest pulse)
    [defaults.analysis]
    max_order = 12
    order = 4                         # optional: a fixed order instead of the order test's choice
    sample_rate_hz = 1.0e6
    dcm_ratio = "auto"                # response-time ratio r of the DCM; "auto" (default): r that
                                      # widens the ±5 % band 3× (analysis.dcm_design)
    dcm_damping = 0.707               # damping ζ_e of the DCM's new poles
    uncertainty = true                # Monte Carlo uncertainty of the key figures (GUM-S1)
    draws = 400                       # its number of draws (default: the analysis' own)

    [[shots]]
    pressure_bar = 1.5
    repeats = 3
    [shots.analysis]                  # optional per-shot overrides
    max_order = 8

    [[shots]]                         # a target level instead of a pressure: automatic level
    peak_g = 50000                    # control (rig/level_control.py) chooses each shot's
    repeats = 3                       # pressure; or peak_m_s2 = 4.9e5

Entries expand in order into planned shots with stable ids "s<entry>-r<repeat>"
(s001-r1, s001-r2, s002-r1, ...). Entry numbers in ids and in error messages count from 1:
"shots[2].pressure_bar" is the pressure of the second [[shots]] table, whose ids are s002-*.
An entry gives one of pressure_bar, peak_m_s2 or peak_g (its own overrides what [defaults] gives).
Pressure upper limits belong to the rig (config/rig.toml [limits]): `rig.campaign.check_plan`
checks every entry against them before the first shot moves anything.

Shot counts. A plan may hold at most MAX_TOTAL_SHOTS shots (checked from the repeats before any
shot is expanded: 10⁹ repeats are a clear error, never a MemoryError). A plan of more than
`confirm_above` shots (default CONFIRM_ABOVE_SHOTS; `hopkinson campaign run --confirm-above N`)
fires only when the operator confirms its exact number (`--shots N`, or the panel's dialog):
`check_shot_count`.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from hopkinson.analysis.params import MAX_ORDER_LIMIT  # one range for a plan and the command line
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.toml_file import read_toml

MIN_DRAWS, MAX_DRAWS = 50, 1_000_000  # as analysis.params checks them
LATER_OPTIONS = {"uncertainty": True, "draws": None}  # analysis options added after plans were in use
MAX_TOTAL_SHOTS = 10_000  # more is a typing error, not a campaign (a shot takes minutes)
CONFIRM_ABOVE_SHOTS = 50  # a plan of more shots needs its number confirmed


@dataclass(frozen=True)
class Accelerometer:
    """The accelerometer under calibration."""

    model: str
    serial: str
    sensitivity_v_per_m_s2: float | None = None  # nominal, at the amplifier output
    sine_calibration: str | None = None  # sine calibration CSV (analysis.sine_comparison), resolved path
    transverse_sensitivity_rel: float | None = None  # stated (datasheet) transverse sensitivity; None: 5 % (issue 40)


@dataclass(frozen=True)
class FurtherAccelerometer:
    """A further accelerometer recorded in the same shots (the rig's response_2 channel)."""

    model: str
    serial: str


@dataclass(frozen=True)
class AnalysisOptions:
    """Analysis settings of a shot (defaults from DESIGN.md and the paper's example)."""

    max_order: int = 12
    order: int | None = None  # None: chosen where the bias-corrected loss stops falling
    sample_rate_hz: float = 1.0e6
    dcm_ratio: float | None = None  # None ("auto"): the r that widens the ±5 % band 3×
    dcm_damping: float = 0.707
    uncertainty: bool = True  # the Monte Carlo uncertainty of the key figures
    draws: int | None = None  # its draws; None: the analysis' default


@dataclass(frozen=True)
class PlannedShot:
    """One shot to fire: a stable id, its settings and its analysis options."""

    id: str  # "s001-r1"
    index: int  # 0-based position in the campaign
    entry: int  # 1-based [[shots]] entry
    repeat: int  # 1-based repeat within the entry
    pressure_bar: float | None  # None: chosen at firing time for target_peak_m_s2
    projectile: int
    analysis: AnalysisOptions
    target_peak_m_s2: float | None = None  # automatic level control (rig/level_control.py)

    def to_dict(self) -> dict[str, Any]:
        """The shot as a dict (the plan's fingerprint is made of these). Options added later
        appear only when set, so a run started before them still resumes."""
        out = asdict(self)
        if out["target_peak_m_s2"] is None:
            del out["target_peak_m_s2"]
        for key, default in LATER_OPTIONS.items():
            if out["analysis"][key] == default:
                del out["analysis"][key]
        return out


@dataclass(frozen=True)
class CampaignPlan:
    """A validated campaign plan with its shots expanded in firing order."""

    path: Path
    name: str
    operator: str
    accelerometer: Accelerometer
    shots: tuple[PlannedShot, ...]
    description: str = ""
    authorise_firing: bool = False
    text: str = ""  # the TOML text as loaded (copied into the run folder)
    accelerometer_2: FurtherAccelerometer | None = None  # recorded on response_2

    def sensor_identities(self) -> dict[str, dict[str, str]]:
        """role -> {"model", "serial"} of the further accelerometers (ShotRequest.sensor_identities)."""
        a = self.accelerometer_2
        return {"response_2": {"model": a.model, "serial": a.serial}} if a is not None else {}

    def shot(self, shot_id: str) -> PlannedShot:
        for s in self.shots:
            if s.id == shot_id:
                return s
        raise KeyError(shot_id)

    @property
    def fingerprint(self) -> str:
        """SHA-256 of what gets fired (ids, settings, analysis): equal plans, equal print."""
        canonical = json.dumps([s.to_dict() for s in self.shots], sort_keys=True)
        return hashlib.sha256(canonical.encode()).hexdigest()


_TOP_KEYS = {"name", "operator", "description", "authorise_firing", "accelerometer", "accelerometer_2", "defaults",
             "shots"}
_ACCEL_KEYS = {"model", "serial", "sensitivity_v_per_m_s2", "sine_calibration", "transverse_sensitivity_rel"}
_SHOT_KEYS = {"pressure_bar", "peak_m_s2", "peak_g", "projectile", "analysis"}
G_M_S2 = 9.80665
_ENTRY_KEYS = _SHOT_KEYS | {"repeats"}
_ANALYSIS_KEYS = set(AnalysisOptions.__dataclass_fields__)


class _Checker:
    """Type and range checks that name the file and the key in every message."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, key: str, reason: str) -> ConfigError:
        return ConfigError(f"{self.path}: {key}: {reason}")

    def table(self, value: Any, key: str, allowed: set[str]) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(key, f"must be a table, got {_kind(value)}")
        unknown = sorted(set(value) - allowed)
        if unknown:
            where = f"{key}." if key else ""
            raise self.fail(
                f"{where}{unknown[0]}", f"unknown key (allowed here: {', '.join(sorted(allowed))})"
            )
        return value

    def text(self, value: Any, key: str, required: bool = True) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, got {_kind(value)}")
        if required and not value.strip():
            raise self.fail(key, "must not be empty")
        return value

    def number(self, value: Any, key: str, low: float, low_open: bool = True,
               high: float = math.inf, high_open: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"must be a number, got {_kind(value)}")
        x = float(value)
        too_low = x <= low if low_open else x < low
        too_high = x >= high if high_open else x > high
        if not math.isfinite(x) or too_low or too_high:
            lo = f"> {low:g}" if low_open else f">= {low:g}"
            hi = "" if high == math.inf else (f" and < {high:g}" if high_open else f" and <= {high:g}")
            raise self.fail(key, f"must be {lo}{hi} (got {value})")
        return x

    def integer(self, value: Any, key: str, low: int, high: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"must be an integer, got {_kind(value)}")
        if value < low or (high is not None and value > high):
            span = f"{low}..{high}" if high is not None else f">= {low}"
            raise self.fail(key, f"must be {span} (got {value})")
        return value


def _kind(value: Any) -> str:
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
             list: "an array", dict: "a table"}
    return names.get(type(value), type(value).__name__)


def load_plan(path: str | Path) -> CampaignPlan:
    """Read and validate a campaign plan; ConfigError names the file, the key and the reason."""
    path = Path(path)
    doc, text = read_toml(path, "plan file", missing="no such plan file")  # bounded: /dev/zero is one line
    return plan_from_dict(doc, path, text)


def plan_from_dict(doc: dict[str, Any], path: Path, text: str = "") -> CampaignPlan:
    """Validate a parsed plan (`path` names it in errors) and expand its shots."""
    c = _Checker(path)
    c.table(doc, "", _TOP_KEYS)
    for key in ("name", "operator", "accelerometer", "shots"):
        if key not in doc:
            raise c.fail(key, "missing (required)")
    name = c.text(doc["name"], "name")
    if any(ch in name for ch in "/\\:") or name.startswith("."):
        raise c.fail("name", f"must be usable as a folder name (got {name!r})")
    operator = c.text(doc["operator"], "operator")
    description = c.text(doc.get("description", ""), "description", required=False)
    authorise = doc.get("authorise_firing", False)
    if not isinstance(authorise, bool):
        raise c.fail("authorise_firing", f"must be true or false, got {_kind(authorise)}")

    acc = c.table(doc["accelerometer"], "accelerometer", _ACCEL_KEYS)
    for key in ("model", "serial"):
        if key not in acc:
            raise c.fail(f"accelerometer.{key}", "missing (required)")
    sensitivity = acc.get("sensitivity_v_per_m_s2")
    accelerometer = Accelerometer(
        c.text(acc["model"], "accelerometer.model"),
        c.text(acc["serial"], "accelerometer.serial"),
        None if sensitivity is None
        else c.number(sensitivity, "accelerometer.sensitivity_v_per_m_s2", 0.0),
        None if acc.get("sine_calibration") is None
        else str(path.parent / c.text(acc["sine_calibration"], "accelerometer.sine_calibration")),
        None if acc.get("transverse_sensitivity_rel") is None
        else c.number(acc["transverse_sensitivity_rel"], "accelerometer.transverse_sensitivity_rel", 0.0, False, 1.0),
    )

    accelerometer_2 = None
    if "accelerometer_2" in doc:
        acc2 = c.table(doc["accelerometer_2"], "accelerometer_2", {"model", "serial"})
        for key in ("model", "serial"):
            if key not in acc2:
                raise c.fail(f"accelerometer_2.{key}", "missing (required)")
        accelerometer_2 = FurtherAccelerometer(c.text(acc2["model"], "accelerometer_2.model"),
                                               c.text(acc2["serial"], "accelerometer_2.serial"))

    defaults = c.table(doc.get("defaults", {}), "defaults", _SHOT_KEYS)
    base = _shot_settings(c, defaults, "defaults", {}, AnalysisOptions())

    entries = doc["shots"]
    if not isinstance(entries, list) or not entries:
        raise c.fail("shots", "must be one or more [[shots]] tables")
    width = max(3, len(str(len(entries))))
    shots: list[PlannedShot] = []
    expanded: list[tuple[int, dict[str, Any], int]] = []
    total = 0
    for number, entry in enumerate(entries, start=1):
        key = f"shots[{number}]"
        entry = c.table(entry, key, _ENTRY_KEYS)
        settings = _shot_settings(c, entry, key, base, base["analysis"])
        if "pressure_bar" not in settings and "target_peak_m_s2" not in settings:
            raise c.fail(f"{key}.pressure_bar", "missing (give pressure_bar, peak_m_s2 or peak_g; no default in [defaults])")
        if "projectile" not in settings:
            raise c.fail(f"{key}.projectile", "missing (and no default in [defaults])")
        repeats = c.integer(entry.get("repeats", 1), f"{key}.repeats", 1, MAX_TOTAL_SHOTS)
        total += repeats
        if total > MAX_TOTAL_SHOTS:
            raise c.fail(f"{key}.repeats", f"the plan would fire more than {MAX_TOTAL_SHOTS} shots "
                                           f"({total} up to this entry): split it into several campaigns")
        expanded.append((number, settings, repeats))
    for number, settings, repeats in expanded:
        for repeat in range(1, repeats + 1):
            shots.append(
                PlannedShot(
                    id=f"s{number:0{width}d}-r{repeat}",
                    index=len(shots),
                    entry=number,
                    repeat=repeat,
                    pressure_bar=settings.get("pressure_bar"),
                    projectile=settings["projectile"],
                    analysis=settings["analysis"],
                    target_peak_m_s2=settings.get("target_peak_m_s2"),
                )
            )
    return CampaignPlan(
        path=path,
        name=name,
        operator=operator,
        accelerometer=accelerometer,
        shots=tuple(shots),
        description=description,
        authorise_firing=authorise,
        text=text,
        accelerometer_2=accelerometer_2,
    )


def _shot_settings(
    c: _Checker, table: dict[str, Any], key: str, inherited: dict[str, Any], analysis: AnalysisOptions
) -> dict[str, Any]:
    """Pressure, projectile and analysis options of a table, over what it inherits."""
    out = dict(inherited)
    levels = [k for k in ("pressure_bar", "peak_m_s2", "peak_g") if k in table]
    if len(levels) > 1:
        raise c.fail(f"{key}.{levels[1]}", f"give one of pressure_bar, peak_m_s2 or peak_g (got {' and '.join(levels)})")
    if "pressure_bar" in table:
        out["pressure_bar"] = c.number(table["pressure_bar"], f"{key}.pressure_bar", 0.0)
        out.pop("target_peak_m_s2", None)
    elif levels:  # a target level: the pressure is chosen when the shot is fired
        scale = G_M_S2 if levels[0] == "peak_g" else 1.0
        out["target_peak_m_s2"] = c.number(table[levels[0]], f"{key}.{levels[0]}", 0.0) * scale
        out.pop("pressure_bar", None)
    if "projectile" in table:
        out["projectile"] = c.integer(table["projectile"], f"{key}.projectile", 1, 3)
    options = asdict(analysis)
    if "analysis" in table:
        akey = f"{key}.analysis"
        given = c.table(table["analysis"], akey, _ANALYSIS_KEYS)
        if "max_order" in given:
            options["max_order"] = c.integer(given["max_order"], f"{akey}.max_order", 1, MAX_ORDER_LIMIT)
        if "order" in given:
            options["order"] = c.integer(given["order"], f"{akey}.order", 1, MAX_ORDER_LIMIT)
        if "sample_rate_hz" in given:
            options["sample_rate_hz"] = c.number(given["sample_rate_hz"], f"{akey}.sample_rate_hz", 0.0)
        if "dcm_ratio" in given and given["dcm_ratio"] == "auto":
            options["dcm_ratio"] = None
        elif "dcm_ratio" in given:
            options["dcm_ratio"] = c.number(given["dcm_ratio"], f"{akey}.dcm_ratio", 1.0, low_open=False)
        if "dcm_damping" in given:
            options["dcm_damping"] = c.number(given["dcm_damping"], f"{akey}.dcm_damping", 0.0, high=1.0)
        if "uncertainty" in given:
            if not isinstance(given["uncertainty"], bool):
                raise c.fail(f"{akey}.uncertainty", f"must be true or false, got {_kind(given['uncertainty'])}")
            options["uncertainty"] = given["uncertainty"]
        if "draws" in given:
            options["draws"] = c.integer(given["draws"], f"{akey}.draws", MIN_DRAWS, MAX_DRAWS)
        if options["order"] is not None and options["order"] > options["max_order"]:
            bad = "order" if "order" in given else "max_order"
            raise c.fail(
                f"{akey}.{bad}",
                f"order {options['order']} exceeds max_order {options['max_order']}",
            )
    out["analysis"] = AnalysisOptions(**options)
    return out


def check_shot_count(plan: CampaignPlan, confirm_above: int = CONFIRM_ABOVE_SHOTS,
                     confirmed_shots: int | None = None) -> None:
    """ConfigError (exit 2, nothing fired) when the plan has more than `confirm_above` shots and
    `confirmed_shots` is not exactly its number of shots (module docstring)."""
    total = len(plan.shots)
    if total <= confirm_above or confirmed_shots == total:
        return
    given = "" if confirmed_shots is None else f" (--shots {confirmed_shots} was given)"
    raise ConfigError(f"{plan.path}: the plan fires {total} shots, more than {confirm_above}: confirm the number "
                      f"with --shots {total}{given}; nothing was fired")
