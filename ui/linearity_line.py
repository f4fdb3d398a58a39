"""The Campaign tab's amplitude linearity line (ISO 16063-22): the fit through the analysed shots'
sensitivities against their amplitudes (reports.statistics), each point with its U in the tooltip."""

from __future__ import annotations

from collections.abc import Iterable

from PySide6.QtWidgets import QLabel, QWidget

from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.reports.statistics import (
    STATIC_GAIN,
    LinearityPoint,
    campaign_linearity,
    fitted_points,
    linearity_points,
)
from hopkinson.rig.plan import G_M_S2


class LinearityLine(QLabel):
    """One line of text, empty until the analysed shots cover two or more levels."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("", parent)
        self.setWordWrap(True)
        self._points: dict[str, LinearityPoint] = {}

    def clear_points(self) -> None:
        """Forget every shot's point (a new plan)."""
        self._points.clear()

    def add(self, sid: str, figures: KeyFigures) -> None:
        """A shot's point from its key figures (replaces the shot's earlier one)."""
        for point in linearity_points([(sid, figures)]):
            self._points[sid] = point

    def show_line(self, shot_ids: Iterable[str]) -> None:
        """Show the line through these shots' points (in this order), or nothing below two levels."""
        points = [self._points[sid] for sid in shot_ids if sid in self._points]
        fit, _note = campaign_linearity(points)
        points = fitted_points(points)
        if fit is None:
            self.setText("")
            self.setToolTip("")
            return
        what = "quasi-static gain" if points[0].kind == STATIC_GAIN else "DC gain"
        self.setText(f"Amplitude linearity (ISO 16063-22), sensitivity ({what}) against the "
                     f"amplitude: slope {fit.text()}")
        lines = [f"{p.label}: {p.peak_m_s2 / G_M_S2:,.0f} g, S {p.sensitivity:.5g}"
                 + (f" ± {p.expanded:.2g}" if p.expanded is not None else "") + f" ({100 * r:+.2f} % from the line)"
                 for p, r in zip(points, fit.residuals_rel, strict=True)]
        self.setToolTip("\n".join(lines))
