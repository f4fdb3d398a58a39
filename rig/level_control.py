"""Automatic level control: the reservoir pressure for a campaign entry's target peak.

A campaign entry may give `peak_m_s2` or `peak_g` instead of `pressure_bar`. Each of its shots is
fired at a pressure chosen from what is known then:

1. the bar model's pressure → peak for the projectile (`model_peak_m_s2`: analysis.bar, the
   rig's `[bar]`: launcher, impact, dispersion, separation; speed ∝ √p, the peak a little faster
   than the speed with a stiffening contact), scaled by
2. a correction factor r = measured peak ÷ model peak, the geometric mean over
   - the shots of this entry already fired and analysed, when there are any (the latest
     `ENTRY_SHOTS_USED`), else
   - this rig's own history for that projectile (`LEVEL_HISTORY_NAME` beside the run folders:
     one JSON line per analysed shot, every campaign's; the latest `HISTORY_SHOTS_USED`), else 1;

so p = model_pressure(target ÷ r). The pressure is never above the rig's maximum (nor below its
minimum): a target the model says needs more is refused at the plan's check, before the first
shot; a correction that asks for more later is held at the maximum, and the shot says so.
Every shot records its target, the pressure chosen and how (`LevelChoice.to_dict`, in the shot
file's settings and the campaign journal).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.fileio import append_json_line

if TYPE_CHECKING:
    from hopkinson.analysis.bar import BarRig

G_M_S2 = 9.80665
LEVEL_HISTORY_NAME = "level-history.jsonl"
ENTRY_SHOTS_USED = 3
HISTORY_SHOTS_USED = 10


def model_peak_m_s2(projectile: int, pressure_bar: float, rig: BarRig | None = None) -> float:
    """The bar model's peak for the projectile fired from `pressure_bar` (the paper's rig
    unless the rig's own `[bar]` is given)."""
    from hopkinson.analysis.bar import (  # NumPy/SciPy: only when a level is chosen
        PAPER_RIG,
        predict_shot,
    )

    return predict_shot(rig or PAPER_RIG, projectile, pressure_bar=max(pressure_bar, 0.0)).peak_m_s2


def model_pressure_bar(projectile: int, peak_m_s2: float, rig: BarRig | None = None) -> float:
    """The bar model's pressure for a peak (the inverse of `model_peak_m_s2`)."""
    from hopkinson.analysis.bar import PAPER_RIG, speed_for_peak

    bar_rig = rig or PAPER_RIG
    if peak_m_s2 == 0:
        return 0.0
    return bar_rig.launcher.pressure_bar(bar_rig.projectile(projectile),
                                         speed_for_peak(bar_rig, projectile, abs(peak_m_s2)))


@dataclass(frozen=True)
class LevelPoint:
    """One analysed shot: the pressure it was fired at and the peak the reference measured."""

    projectile: int
    pressure_bar: float
    peak_m_s2: float

    def ratio(self, rig: BarRig | None = None) -> float:
        """Measured ÷ model peak at this pressure."""
        return abs(self.peak_m_s2) / model_peak_m_s2(self.projectile, self.pressure_bar, rig)


@dataclass(frozen=True)
class LevelChoice:
    """The pressure chosen for a target peak, and what it was chosen from."""

    target_peak_m_s2: float
    pressure_bar: float
    predicted_peak_m_s2: float  # at `pressure_bar`, after the correction
    correction: float  # r: measured ÷ model peak
    basis: str  # "model" | "rig history" | "this entry"
    points_used: int
    held_at_limit: bool = False  # the correction asked for more than the rig's maximum (or less than its minimum)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def choose_pressure(target_peak_m_s2: float, projectile: int, history: Iterable[LevelPoint] = (),
                    entry_shots: Sequence[LevelPoint] = (), *, min_pressure_bar: float = 0.0,
                    max_pressure_bar: float = math.inf, rig: BarRig | None = None) -> LevelChoice:
    """The pressure for `target_peak_m_s2` (module docstring): entry shots first, then the rig's
    history of this projectile, then the model alone; held within the rig's limits."""
    used: list[LevelPoint] = [p for p in entry_shots if p.projectile == projectile and _usable(p)][-ENTRY_SHOTS_USED:]
    basis = "this entry"
    if not used:
        used = [p for p in history if p.projectile == projectile and _usable(p)][-HISTORY_SHOTS_USED:]
        basis = "rig history"
    if used:
        correction = math.exp(sum(math.log(p.ratio(rig)) for p in used) / len(used))
    else:
        correction, basis = 1.0, "model"
    wanted = model_pressure_bar(projectile, target_peak_m_s2 / correction, rig)
    pressure = min(max(wanted, min_pressure_bar), max_pressure_bar)
    return LevelChoice(float(target_peak_m_s2), float(pressure), correction * model_peak_m_s2(projectile, pressure, rig),
                       float(correction), basis, len(used), held_at_limit=pressure != wanted)


def needed_pressure_bar(target_peak_m_s2: float, projectile: int, history: Iterable[LevelPoint] = (),
                        rig: BarRig | None = None) -> LevelChoice:
    """The first shot's choice without any limit: what the plan's check compares with the rig's maximum."""
    return choose_pressure(target_peak_m_s2, projectile, history, rig=rig)


def _usable(p: LevelPoint) -> bool:
    return p.pressure_bar > 0 and math.isfinite(p.peak_m_s2) and p.peak_m_s2 != 0


# -- the rig's history ----------------------------------------------------------------------------
def history_path(runs_dir: str | Path) -> Path:
    return Path(runs_dir) / LEVEL_HISTORY_NAME


def read_history(path: str | Path) -> list[LevelPoint]:
    """The rig's pressure → peak history (a missing file: none; a damaged line is skipped)."""
    path = Path(path)
    if not path.is_file():
        return []
    points = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            d = json.loads(line)
            points.append(LevelPoint(int(d["projectile"]), float(d["pressure_bar"]), float(d["peak_m_s2"])))
        except (ValueError, KeyError, TypeError):
            continue
    return points


def append_history(path: str | Path, point: LevelPoint, **tags: Any) -> None:
    """Append one analysed shot to the rig's history (one fsynced JSON line)."""
    append_json_line(path, {**asdict(point), **tags})


def measured_peak_m_s2(results: dict[str, Any] | None) -> float | None:
    """The reference's peak acceleration of an analysis' results (None when there is none)."""
    reduction = (results or {}).get("reduction") or {}
    value = reduction.get("peak_acceleration_m_s2")
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else None
