"""What the rig hands the lab's record: one shot as its file holds it (built by
hopkinson.rig.lab_record from a shot file), a rig's reference chain, and the checks a record
passes before any database sees it (`check_record`: the same refusal on SQLite and
PostgreSQL)."""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field
from typing import Any

from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.lab.errors import RecordRejected
from hopkinson.lab.schema import FIGURE_KEYS

# Marks of simulated data in instrument identities (drivers/sim's *IDN? and Modbus identities)
SIMULATOR_IDENTITY = re.compile(r"hopkinson[-_ ]?sim|\bSIM(?:AMP|DIG|VAC)\b", re.IGNORECASE)
TEXT_LIMITS = {"operator": 200, "shot_name": 200, "accelerometer_model": 200, "accelerometer_serial": 120,
               "rig": 120, "campaign": 200, "software_version": 60}


def normal_serial(serial: str) -> str:
    """A serial number as the record keys it: spaces collapsed, upper case ("sn-7 " -> "SN-7")."""
    return " ".join(str(serial).split()).upper()


@dataclass(frozen=True)
class ReferenceLink:
    """One item of a rig's reference chain and its own calibration certificate."""

    item: str
    certificate: str
    issued_by: str = ""
    u_rel: float | None = None  # relative standard uncertainty, k = 1
    due: str = ""  # YYYY-MM-DD: when its own calibration is due


@dataclass(frozen=True)
class ShotRecord:
    """One shot file's content for the record (never the raw data: its SHA-256 only)."""

    uuid: str
    raw_sha256: str  # of the raw channels: unchanged by a re-analysis
    file_sha256: str  # of the file as it is now (names the analysis it holds)
    path: str
    state: str  # "raw", "analysed" or "analysis_failed"
    operator: str
    utc_time: str
    accelerometer_model: str
    accelerometer_serial: str
    pressure_bar: float
    projectile: int
    simulated_marks: tuple[str, ...] = ()  # every mark of simulated data the file carries
    software_version: str = ""
    rig: str = ""
    campaign_uuid: str = ""  # the campaign's identity ("" for a lone shot)
    campaign: str = ""  # the run folder's name, for people
    campaign_path: str = ""
    shot_name: str = ""
    reference_chain: tuple[ReferenceLink, ...] = ()
    analysis_error: str = ""
    analysed_utc: str = ""
    analysis_software_version: str = ""
    response_unit: str = ""
    peak_acceleration_m_s2: float | None = None
    pulse_width_s: float | None = None
    figures: dict[str, Figure | None] = field(default_factory=dict)  # FIGURE_KEYS -> Figure
    # the quasi-static gain (analysis.static_gain, u shot-specific) and the amplitude it is measured at
    static_gain: Figure | None = None
    static_gain_amplitude_m_s2: float | None = None
    # what a certificate states besides the figures: amplifier settings and identities, the
    # sensitivity the response was scaled by, the uncertainty budget's reference inputs
    context: dict[str, Any] = field(default_factory=dict)

    @property
    def simulated(self) -> bool:
        return bool(self.simulated_marks)

    @property
    def serial(self) -> str:
        return normal_serial(self.accelerometer_serial)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the spool's line)."""
        out = asdict(self)
        out["figures"] = {k: f.to_dict() if f is not None else None for k, f in self.figures.items()}
        out["static_gain"] = self.static_gain.to_dict() if self.static_gain is not None else None
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ShotRecord:
        data = dict(data)
        if "simulated" in data:  # a spool line written before the marks were kept
            data.setdefault("simulated_marks", ["flag"] if data["simulated"] else [])
            del data["simulated"]
        data["simulated_marks"] = tuple(data.get("simulated_marks") or ())
        data["reference_chain"] = tuple(ReferenceLink(**r) for r in data.get("reference_chain") or ())
        data["figures"] = {k: Figure.of(v) for k, v in (data.get("figures") or {}).items()}
        data["static_gain"] = Figure.of(data.get("static_gain"))
        known = set(cls.__dataclass_fields__)
        return cls(**{k: v for k, v in data.items() if k in known})


def check_record(record: ShotRecord) -> None:
    """RecordRejected naming the field when a record cannot be kept as it is (the same limits
    on every database: PostgreSQL would refuse what SQLite stores)."""
    for name, limit in TEXT_LIMITS.items():
        value = str(getattr(record, name))
        if len(value) > limit:
            raise RecordRejected(f"shot {record.uuid} ({record.path}): {name} is {len(value)} characters long, "
                                 f"at most {limit} are kept; not recorded")


def figures_of(key_figures: KeyFigures) -> dict[str, Figure | None]:
    """FIGURE_KEYS -> the shot's Figure (FBSD edges known only as a bound are left out)."""
    out: dict[str, Figure | None] = {
        "sensitivity": key_figures.sensitivity,
        "shock_sensitivity": key_figures.shock_sensitivity,
        "natural_frequency_hz": key_figures.natural_frequency_hz,
        "damping_ratio": key_figures.damping_ratio,
    }
    for level in ("5", "10"):
        bounded = level in key_figures.fbsd_bounds
        out[f"fbsd_{level}_hz"] = None if bounded else key_figures.fbsd_hz.get(level)
    assert tuple(out) == FIGURE_KEYS
    return out
