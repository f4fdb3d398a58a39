"""Across the shots of a campaign: the spread of each key figure and the cross-validation matrix.

- spread: mean, sample standard deviation (n − 1) and coefficient of variation of the main
  mode's f_n and ζ, the FBSD (±5 %, ±10 %), the shock sensitivity and the fit;
- cross-validation (the paper's "multi-group data" check): entry [i, j] is the fit % of
  model i simulated on shot j's reference against shot j's measured response,
  100·(1 − ‖y − ŷ‖/‖y − ȳ‖), the measure `analysis.identify` reports for its own shot (the
  diagonal equals each shot's own fit). Shot j's channels are prepared as the identification
  prepared them (its baselines and input delay, stored in its results).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.identify import fit_percent
from hopkinson.analysis.response import model_output
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.reports.data import (
    QUANTITIES,
    ShotEntry,
    figures_of_merit,
    model_delay_samples,
    prepared_channels,
)


def spread(values: Iterable[float | None]) -> dict[str, float | int | None]:
    """Mean, sample standard deviation (n − 1), coefficient of variation (%) and n of the known values."""
    x = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    n = int(x.size)
    if n == 0:
        return {"n": 0, "mean": None, "std": None, "cv_percent": None, "min": None, "max": None}
    mean = float(np.mean(x))
    std = float(np.std(x, ddof=1)) if n > 1 else None
    cv = 100.0 * std / abs(mean) if std is not None and mean != 0 else None
    return {"n": n, "mean": mean, "std": std, "cv_percent": cv, "min": float(np.min(x)), "max": float(np.max(x))}


def cross_validation(analyses: Sequence[ShotAnalysis]) -> np.ndarray:
    """Fit % of model i (with its delay) on shot j's record: matrix [i, j]; NaN where it cannot be computed."""
    n = len(analyses)
    out = np.full((n, n), np.nan)
    for i, a in enumerate(analyses):
        d = model_delay_samples(a)
        for j, b in enumerate(analyses):
            if not math.isclose(a.model.sample_interval_s, b.model.sample_interval_s, rel_tol=1e-6):
                continue
            try:
                u, y = prepared_channels(b, d)
                out[i, j] = fit_percent(y, model_output(a.model, u))
            except AnalysisError:
                pass
    return out


@dataclass
class CampaignStatistics:
    """Across the analysed shots: per-shot figures, their spread, the cross-validation matrix."""

    labels: list[str]  # the analysed shots, in order
    figures: list[dict[str, Any]]  # figures_of_merit per analysed shot
    spread: dict[str, dict[str, float | int | None]]  # quantity key -> spread()
    cross_validation_percent: np.ndarray  # [i, j]: model i on shot j

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (strict JSON: a NaN or infinite figure becomes None)."""
        return json_safe({"shots": self.labels, "figures": self.figures, "spread": self.spread,
                           "cross_validation_percent": self.cross_validation_percent.tolist(),
                           "cross_validation_note": "row i: model of shot i; column j: simulated on shot j's "
                                                    "reference; fit % = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖)"})


def json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def campaign_statistics(entries: Sequence[ShotEntry]) -> CampaignStatistics:
    """Spread and cross-validation over the entries that have an analysis."""
    analysed = [e for e in entries if e.analysis is not None]
    figures = [figures_of_merit(e) for e in analysed]
    keys = [k for k, *_ in QUANTITIES] + ["sensitivity_v_per_m_s2", "peak_acceleration_m_s2", "pulse_width_s"]
    stats = {k: spread(f[k] for f in figures) for k in keys}
    matrix = cross_validation([e.analysis for e in analysed])  # type: ignore[misc]
    return CampaignStatistics([e.label for e in analysed], figures, stats, matrix)
