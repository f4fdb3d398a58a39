"""A shot file's verdict and its sensitivity in the sensor's own unit, from the file alone.

`shot_judgement(shot)` reads what the shot recorded besides its analysis: the sensitivity unit
and tolerance its set-up named (shot_settings "sensitivity_unit", "sensitivity_tolerance_percent"),
the nominal sensitivity the analysis divided the response by (its stored params), and the target
level it was fired for (shot_settings "level_control"); then judges it (analysis.verdict) and
gives the measured sensitivity as an absolute value in that unit with its ratio to nominal
(analysis.sensitivity_units). The panel, the campaign table and the commands show the same.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.analysis.sensitivity_units import (
    DEFAULT_UNIT,
    UNITS,
    AbsoluteSensitivity,
    SensitivityUnit,
    absolute_sensitivity,
    sensitivity_unit,
)
from hopkinson.analysis.verdict import ShotVerdict, VerdictCriteria, shot_verdict
from hopkinson.rig.shotfile import Shot


@dataclass(frozen=True)
class ShotJudgement:
    """A shot's key figures (None when not analysed), its verdict and its absolute sensitivity."""

    figures: KeyFigures | None
    verdict: ShotVerdict
    sensitivity: AbsoluteSensitivity | None
    shock_sensitivity: AbsoluteSensitivity | None
    unit: SensitivityUnit
    nominal_si: float | None
    tolerance_percent: float | None
    target_peak_m_s2: float | None


def settings_of(shot: Shot) -> dict[str, Any]:
    config = shot.meta.config if isinstance(shot.meta.config, dict) else {}
    settings = config.get("shot_settings")
    return settings if isinstance(settings, dict) else {}


def judge(results: dict[str, Any] | None, settings: dict[str, Any], analysis_error: str | None = None,
          criteria: VerdictCriteria | None = None) -> ShotJudgement:
    """The judgement of a results dict and the shot settings it was fired with (module docstring);
    `criteria`: the verdict's limits (the tolerance recorded with the shot is used unless given)."""
    unit = _unit(settings.get("sensitivity_unit"))
    tolerance = _positive(settings.get("sensitivity_tolerance_percent"))
    level = settings.get("level_control")
    target = _positive(level.get("target_peak_m_s2")) if isinstance(level, dict) else None
    params = (results or {}).get("params") or {}
    nominal = _positive(params.get("sensitivity_v_per_m_s2")) or _positive(settings.get("sensitivity_v_per_m_s2"))
    criteria = criteria or VerdictCriteria(tolerance_percent=tolerance)
    figures = KeyFigures.from_results(results) if results and not analysis_error and "model" in results else None
    verdict = shot_verdict(figures, criteria, target_peak_m_s2=target, analysis_error=analysis_error)
    sensitivity = shock = None
    if figures is not None:
        s = figures.sensitivity
        sensitivity = absolute_sensitivity(s.value, s.expanded, figures.response_unit, nominal, unit)
        sh = figures.shock_sensitivity
        if sh is not None:
            shock = absolute_sensitivity(sh.value, sh.expanded, figures.response_unit, nominal, unit)
    return ShotJudgement(figures, verdict, sensitivity, shock, unit, nominal, criteria.tolerance_percent, target)


def shot_judgement(shot: Shot, criteria: VerdictCriteria | None = None) -> ShotJudgement:
    """Judge a shot read from its file (module docstring)."""
    error = shot.analysis_error or (None if shot.results else "the shot has not been analysed")
    return judge(shot.results, settings_of(shot), error, criteria)


def _unit(name: Any) -> SensitivityUnit:
    if isinstance(name, str):
        try:
            return sensitivity_unit(name)
        except ValueError:
            pass
    return UNITS[DEFAULT_UNIT]


def _positive(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) and value > 0 else None
