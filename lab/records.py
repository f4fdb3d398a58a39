"""What the rig hands the lab's record: one shot as its file holds it (built by
hopkinson.rig.lab_record from a shot file), and a rig's reference chain."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.lab.schema import FIGURE_KEYS


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
    simulated: bool = False
    software_version: str = ""
    rig: str = ""
    campaign: str = ""  # the run folder's name ("" for a lone shot)
    campaign_path: str = ""
    shot_name: str = ""
    reference_chain: tuple[ReferenceLink, ...] = ()
    analysis_error: str = ""
    analysed_utc: str = ""
    analysis_software_version: str = ""
    response_unit: str = ""
    peak_acceleration_m_s2: float | None = None
    figures: dict[str, Figure | None] = field(default_factory=dict)  # FIGURE_KEYS -> Figure

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the spool's line)."""
        out = asdict(self)
        out["figures"] = {k: f.to_dict() if f is not None else None for k, f in self.figures.items()}
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ShotRecord:
        data = dict(data)
        data["reference_chain"] = tuple(ReferenceLink(**r) for r in data.get("reference_chain") or ())
        data["figures"] = {k: Figure.of(v) for k, v in (data.get("figures") or {}).items()}
        return cls(**data)


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
