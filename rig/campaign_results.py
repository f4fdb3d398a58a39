"""What a campaign tells: where it is (`CampaignProgress`), how it ended (`CampaignOutcome`), and
each shot's figures as one line (`result_line`) and as the journal's info (`result_info`).
The runner is rig/campaign.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.rig.journal import ShotState, ShotStatus
from hopkinson.rig.level_control import measured_peak_m_s2
from hopkinson.rig.shot import ShotOutcome

S = ShotState


@dataclass(frozen=True)
class CampaignProgress:
    """Where the campaign is: shot `index` (1-based) of `total`, its id and attempt."""

    index: int
    total: int
    shot_id: str
    pressure_bar: float
    projectile: int

    @property
    def prefix(self) -> str:
        """"[3/8] s002-r1": what every progress line starts with."""
        return f"[{self.index}/{self.total}] {self.shot_id}"


@dataclass
class CampaignOutcome:
    """How a campaign run ended."""

    run_folder: Path
    exit_code: int
    message: str
    summary: dict[str, Any]  # Journal.summary() at the end
    fired_this_run: list[str] = field(default_factory=list)
    resume_report: list[dict[str, Any]] = field(default_factory=list)
    last_shot: ShotOutcome | None = None

    @property
    def complete(self) -> bool:
        return bool(self.summary.get("complete"))

    def to_dict(self) -> dict[str, Any]:
        return {
            "run_folder": str(self.run_folder),
            "exit_code": self.exit_code,
            "message": self.message,
            "complete": self.complete,
            "fired_this_run": list(self.fired_this_run),
            "resume_report": list(self.resume_report),
            "analyses_failed": analyses_failed(self.summary),
            "summary": self.summary,
            "last_shot": self.last_shot.to_dict() if self.last_shot is not None else None,
        }


def analyses_failed(summary: dict[str, Any]) -> list[str]:
    """The ids of the shots whose analysis failed (journal state ANALYSIS_FAILED)."""
    return [shot["id"] for shot in summary.get("shots", []) if shot.get("state") == S.ANALYSIS_FAILED.value]


def result_info(results: dict[str, Any] | None) -> dict[str, Any]:
    """A few figures of an analysis for the journal's info (the shot file holds the rest)."""
    if not results:
        return {}
    info: dict[str, Any] = {}
    model = results.get("model") or {}
    if "order" in model:
        info["order"] = model["order"]
    if results.get("fbsd_hz"):
        info["fbsd_hz"] = results["fbsd_hz"]
    peak = measured_peak_m_s2(results)
    if peak is not None:  # the level control's measure of the shot
        info["peak_m_s2"] = peak
    return info


def resume_text(item: dict[str, Any]) -> str:
    if item.get("shot_id") is None:
        return f"resume: {item.get('action', 'note')}: {item.get('path', '')}"
    if item.get("from") == item.get("to"):
        return f"resume: {item['shot_id']}: {item['reason']}"
    return f"resume: {item['shot_id']}: {item['from']} -> {item['to']}: {item['reason']}"


def shot_end_text(status: ShotStatus, outcome: ShotOutcome) -> str:
    text = status.state.value
    if status.state == S.ANALYSED and outcome.results:
        text += " " + result_line(outcome.results)
    elif outcome.analysis_error:
        text += f": {outcome.analysis_error}"
    elif outcome.error:
        text += f": {outcome.error}"
    return text


def result_line(results: dict[str, Any]) -> str:
    """One line of an analysis' key figures (analysis.key_figures, as the report and the panel
    show them): order, f_n and ζ of the main mode as value ± U (k ≈ 2), or why there is none,
    FBSD ±5 %/±10 % (a bound where the excitation does not support the edge)."""
    kf = KeyFigures.from_results(results)
    parts = [f"order {kf.order}"] if kf.order is not None else []
    f_n = kf.natural_frequency_hz
    if f_n is not None and f_n.value is not None:
        parts.append(f"f_n {f_n.format(1e3, unit='kHz')}")
        if kf.damping_ratio is not None and kf.damping_ratio.value is not None:
            parts.append(f"zeta {kf.damping_ratio.format()}")
    else:
        band = kf.supported_band_hz
        parts.append("no resonance in the supported band"
                     + (f" ({band[0] / 1e3:.3g}-{band[1] / 1e3:.3g} kHz): f_n not claimed" if band else ""))
    if kf.fbsd_hz or kf.fbsd_bounds:
        parts.append(f"FBSD ±5 % {kf.fbsd_text('5')}, ±10 % {kf.fbsd_text('10')}")
    return ", ".join(parts)
