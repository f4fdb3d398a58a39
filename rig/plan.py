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
    transverse_sensitivity_rel = 0.05 # optional: its stated (datasheet) transverse sensitivity (default:
                                      # the rig config's [uncertainty] one, 5 % as shipped)
    asymmetry_bound_rel = 0.03        # optional: a bound on its tension/compression asymmetry, carried
                                      # where a pulse drives one direction only (default: the rig's)
    sensitivity_unit = "µV/(m/s²)"    # optional: the unit results show it in (analysis.sensitivity_units)
    tolerance_percent = 5.0           # optional: the sensor's tolerance on its nominal (each shot's verdict)
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
Pressure upper limits belong to the rig (config/rig.toml [limits]): `rig.campaign_setup.check_plan`
checks every entry against them before the first shot moves anything.

Shot counts. A plan may hold at most MAX_TOTAL_SHOTS shots (checked from the repeats before any
shot is expanded: 10⁹ repeats are a clear error, never a MemoryError). A plan of more than
`confirm_above` shots (default CONFIRM_ABOVE_SHOTS; `hopkinson campaign run --confirm-above N`)
fires only when the operator confirms its exact number (`--shots N`, or the panel's dialog):
`check_shot_count`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, Field

from hopkinson.drivers.config_fields import SECTION, Flag, Hint, Int, Number, Text
from hopkinson.rig.config_analysis import options_section
from hopkinson.rig.config_errors import validate
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan_limits import CONFIRM_ABOVE_SHOTS, MAX_TOTAL_SHOTS
from hopkinson.rig.toml_file import read_toml

LATER_OPTIONS = {"uncertainty": True, "draws": None}  # analysis options added after plans were in use
G_M_S2 = 9.80665


def _not_blank(text: str) -> str:
    if not text.strip():
        raise ValueError("must not be empty")
    return text


def _folder_name(name: str) -> str:
    if any(ch in name for ch in "/\\:") or name.startswith("."):
        raise ValueError(f"must be usable as a folder name (got {name!r})")
    return name


def _unit_name(name: str | None) -> str | None:
    """A sensitivity unit as analysis.sensitivity_units names it ("uV/(m/s^2)" → "µV/(m/s²)")."""
    if name is None:
        return None
    from hopkinson.analysis.sensitivity_units import sensitivity_unit

    return sensitivity_unit(name).name


Name = Annotated[Text, AfterValidator(_not_blank)]
Positive = Annotated[Number, Field(gt=0)]


@dataclass(frozen=True)
class Accelerometer:
    """[accelerometer]: the accelerometer under calibration."""

    __pydantic_config__ = SECTION
    model: Name
    serial: Name
    sensitivity_v_per_m_s2: Annotated[Positive | None, Field(description=(
        "nominal sensitivity at the amplifier output, V per m/s²"))] = None
    sine_calibration: Annotated[Text | None, Field(description=(
        "a sine calibration CSV (frequency_hz, magnitude, phase_deg[, u_magnitude_rel, u_phase_deg]), "
        "relative to the plan's folder"))] = None  # once loaded: the resolved path
    sensitivity_unit: Annotated[Text | None, AfterValidator(_unit_name), Field(description=(
        'the unit results show the sensitivity in (analysis.sensitivity_units), e.g. "mV/g"'))] = None
    tolerance_percent: Annotated[Annotated[Number, Field(gt=0, lt=100)] | None, Field(description=(
        "the sensor's tolerance on its nominal sensitivity, per cent: a shot beyond it is flagged"))] = None
    transverse_sensitivity_rel: Annotated[Annotated[Number, Field(ge=0, le=1)] | None, Field(description=(
        "its stated (datasheet) transverse sensitivity, a fraction; unset: the rig config's [uncertainty] "
        "transverse_sensitivity_rel (a Type B row of the budget)"))] = None
    asymmetry_bound_rel: Annotated[Annotated[Number, Field(ge=0, le=1)] | None, Field(description=(
        "a bound on its tension/compression asymmetry |ε|, a fraction, carried where a pulse drives one direction "
        "only; unset: the rig config's [uncertainty] asymmetry_bound_rel (a Type B row of the budget)"))] = None


@dataclass(frozen=True)
class FurtherAccelerometer:
    """[accelerometer_2]: a further accelerometer recorded in the same shots (the rig's
    response_2 channel)."""

    __pydantic_config__ = SECTION
    model: Name
    serial: Name


# [defaults.analysis] and [shots.analysis]: a shot's analysis options, each declared once in
# analysis/options.py (rig/config_analysis.py makes the section); a table gives only the keys it
# changes; draws not given: the rig's [uncertainty] draws. A plan asks a DCM ratio of at least 1.
PlanAnalysis = options_section(
    "PlanAnalysis", __name__, "[defaults.analysis] and [shots.analysis]: analysis settings of a shot (defaults "
    "from analysis.options); a table gives only the keys it changes.",
    ("max_order", "order", "sample_rate_hz", "dcm_ratio", "dcm_damping", "uncertainty", "draws"),
    unset=("draws",), words={"dcm_ratio": {"auto": None}}, narrower={"dcm_ratio": {"ge": 1}})


@dataclass(frozen=True)
class PlannedShot:
    """One shot to fire: a stable id, its settings and its analysis options."""

    id: str  # "s001-r1"
    index: int  # 0-based position in the campaign
    entry: int  # 1-based [[shots]] entry
    repeat: int  # 1-based repeat within the entry
    pressure_bar: float | None  # None: chosen at firing time for target_peak_m_s2
    projectile: int
    analysis: PlanAnalysis
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


# -- the file as written ----------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class ShotTable:
    """[defaults]: what every [[shots]] entry inherits; an entry overrides any of it."""

    __pydantic_config__ = SECTION
    pressure_bar: Annotated[Positive | None, Field(description="reservoir pressure, bar (the rig's limits "
                                                              "apply too)")] = None
    peak_m_s2: Annotated[Positive | None, Field(description="a target level instead of a pressure "
                                                           "(automatic level control)")] = None
    peak_g: Annotated[Positive | None, Field(description="the target level in g")] = None
    projectile: Annotated[Annotated[Int, Field(ge=1, le=3)] | None, Field(description=(
        "1, 2 or 3; No. 3 gives the shortest pulse"))] = None
    analysis: PlanAnalysis | None = None


@dataclass(frozen=True, kw_only=True)
class ShotEntry(ShotTable):
    """[[shots]]: one entry, fired `repeats` times in a row."""

    repeats: Annotated[Int, Field(ge=1, le=MAX_TOTAL_SHOTS, description="how many shots this entry fires")] = 1


@dataclass(frozen=True, kw_only=True)
class PlanFile:
    """A campaign plan file (config/campaigns/*.toml) as written."""

    __pydantic_config__ = SECTION
    name: Annotated[Name, AfterValidator(_folder_name), Field(description="campaign name: run folders are named "
                                                                          "after it")]
    operator: Name
    description: Text = ""
    authorise_firing: Annotated[Flag, Field(description="true: the plan authorises FIRE for its shots "
                                                        "(no --yes)")] = False
    accelerometer: Accelerometer
    accelerometer_2: FurtherAccelerometer | None = None
    defaults: ShotTable = dataclasses.field(default_factory=ShotTable)
    shots: Annotated[tuple[ShotEntry, ...], Field(min_length=1, description="the entries, fired in order"),
                     Hint("one or more [[shots]] tables")]


def load_plan(path: str | Path) -> CampaignPlan:
    """Read and validate a campaign plan; ConfigError names the file, the key and the reason."""
    path = Path(path)
    doc, text = read_toml(path, "plan file", missing="no such plan file")  # bounded: /dev/zero is one line
    return plan_from_dict(doc, path, text)


def plan_from_dict(doc: dict[str, Any], path: Path, text: str = "") -> CampaignPlan:
    """Validate a parsed plan (`path` names it in errors) and expand its shots."""
    plan = validate(PlanFile, doc, path, first_index=1, symbolic=True)
    accelerometer = plan.accelerometer
    if accelerometer.sine_calibration is not None:
        accelerometer = dataclasses.replace(accelerometer,
                                            sine_calibration=str(path.parent / accelerometer.sine_calibration))
    raw_defaults = doc.get("defaults", {})
    base = _shot_settings(plan.defaults, raw_defaults, path, "defaults", {}, PlanAnalysis())
    width = max(3, len(str(len(plan.shots))))
    shots: list[PlannedShot] = []
    expanded: list[tuple[int, dict[str, Any], int]] = []
    total = 0
    for number, (entry, raw) in enumerate(zip(plan.shots, doc["shots"], strict=True), start=1):
        key = f"shots[{number}]"
        settings = _shot_settings(entry, raw, path, key, base, base["analysis"])
        if "pressure_bar" not in settings and "target_peak_m_s2" not in settings:
            raise ConfigError(f"{path}: {key}.pressure_bar: missing (give pressure_bar, peak_m_s2 or peak_g; "
                              "no default in [defaults])")
        if "projectile" not in settings:
            raise ConfigError(f"{path}: {key}.projectile: missing (and no default in [defaults])")
        total += entry.repeats
        if total > MAX_TOTAL_SHOTS:
            raise ConfigError(f"{path}: {key}.repeats: the plan would fire more than {MAX_TOTAL_SHOTS} shots "
                              f"({total} up to this entry): split it into several campaigns")
        expanded.append((number, settings, entry.repeats))
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
        name=plan.name,
        operator=plan.operator,
        accelerometer=accelerometer,
        shots=tuple(shots),
        description=plan.description,
        authorise_firing=plan.authorise_firing,
        text=text,
        accelerometer_2=plan.accelerometer_2,
    )


def _shot_settings(table: ShotTable, raw: dict[str, Any], path: Path, key: str, inherited: dict[str, Any],
                   analysis: PlanAnalysis) -> dict[str, Any]:
    """Pressure, projectile and analysis options of a validated table over what it inherits;
    `raw` (the table as written) tells which analysis keys it gives."""
    out = dict(inherited)
    levels = [k for k in ("pressure_bar", "peak_m_s2", "peak_g") if getattr(table, k) is not None]
    if len(levels) > 1:
        raise ConfigError(f"{path}: {key}.{levels[1]}: give one of pressure_bar, peak_m_s2 or peak_g "
                          f"(got {' and '.join(levels)})")
    if table.pressure_bar is not None:
        out["pressure_bar"] = table.pressure_bar
        out.pop("target_peak_m_s2", None)
    elif levels:  # a target level: the pressure is chosen when the shot is fired
        scale = G_M_S2 if levels[0] == "peak_g" else 1.0
        out["target_peak_m_s2"] = getattr(table, levels[0]) * scale
        out.pop("pressure_bar", None)
    if table.projectile is not None:
        out["projectile"] = table.projectile
    options = asdict(analysis)
    if table.analysis is not None:
        given = raw.get("analysis", {})
        options.update({name: getattr(table.analysis, name) for name in given})
        if options["order"] is not None and options["order"] > options["max_order"]:
            bad = "order" if "order" in given else "max_order"
            raise ConfigError(f"{path}: {key}.analysis.{bad}: order {options['order']} exceeds max_order "
                              f"{options['max_order']}")
    out["analysis"] = PlanAnalysis(**options)
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
