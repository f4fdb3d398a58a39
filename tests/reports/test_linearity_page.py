"""The campaign report's amplitude-linearity page (issue 19, item 5): each shot's shock sensitivity
against its peak with U, the fitted line, the table; the statistics' choice of when there is a
line at all."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from hopkinson.reports.campaign_pages import LINEARITY_CAPTION, linearity_page
from hopkinson.reports.statistics import (
    DC_GAIN,
    STATIC_GAIN,
    CampaignStatistics,
    LinearityPoint,
    campaign_linearity,
    fitted_points,
)

G = 9.80665
PEAKS_G = (20_000, 40_000, 60_000, 80_000)
C = -1.0e-7  # −1 % per 100 km/s²


def _points(peaks_g=PEAKS_G, u: float | None = 0.004) -> list[LinearityPoint]:
    out = []
    for n, g in enumerate(peaks_g, start=1):
        s = 1.5 * (1 + C * g * G)
        out.append(LinearityPoint(f"s00{n}-r1", g * G, s, None if u is None else u,
                                  None if u is None else 1.96 * u))
    return out


def test_a_line_needs_two_levels_and_says_why_not() -> None:
    fit, note = campaign_linearity(_points())
    assert fit is not None and note == "" and fit.slope_rel_per_m_s2 == pytest.approx(C, rel=1e-9)
    assert campaign_linearity(_points((40_000, 40_500)))[0] is None
    assert "one level" in campaign_linearity(_points((40_000, 40_500)))[1]
    assert "two or more levels" in campaign_linearity(_points((40_000,)))[1]
    fit, note = campaign_linearity(_points(u=None))  # no u: equal weights, the scatter's own
    assert fit is not None and "equal weights" in note


def test_the_linearity_page_plots_and_tables_every_point(artifacts_dir: Path) -> None:
    points = _points()
    fit, _ = campaign_linearity(points)
    stats = CampaignStatistics([p.label for p in points], [], {}, np.zeros((0, 0)), linearity_points=points,
                               linearity=fit)
    fig = linearity_page(stats)
    fig.savefig(artifacts_dir / "report-linearity.png", dpi=80)
    assert LINEARITY_CAPTION in fig._suptitle.get_text()
    (table,) = [t for ax in fig.axes for t in ax.tables]
    cells = {(r, c): cell.get_text().get_text() for (r, c), cell in table.get_celld().items()}
    rows = {cells[(r, 0)]: [cells[(r, c)] for c in range(6)] for r in range(1, len(points) + 2)}
    assert rows["s002-r1"][1] == "40,000" and rows["s002-r1"][3] == f"{1.5 * (1 + C * 40_000 * G):.5g}"
    assert rows["linearity"][3] == f"deviation {100 * C * 60_000 * G:+.3g} %"
    assert not any(re.search(r"\d[eE][+-]?\d", text) for text in cells.values())  # no scientific notation
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for cell in table.get_celld().values():  # every text inside its cell
        box, inner = cell.get_window_extent(renderer), cell.get_text().get_window_extent(renderer)
        if cell.get_text().get_text().strip():
            assert box.x0 - 0.5 <= inner.x0 and inner.x1 <= box.x1 + 0.5, cell.get_text().get_text()
    # the fitted line is drawn through the points: its value at each point's peak is the point's
    line = next(ln for ax in fig.axes for ln in ax.get_lines() if ln.get_label().startswith("fit:"))
    x, y = line.get_data()
    assert np.interp(60_000, x, y) == pytest.approx(1.5 * (1 + C * 60_000 * G), rel=1e-3)


def test_a_line_goes_through_one_kind_of_sensitivity_and_says_which() -> None:
    """Shots analysed before the quasi-static gain (their DC gain at Σ|a|³/Σa²) are not mixed with
    newer ones: left out with a note; a campaign of only older shots is fitted to their DC gains and
    says so."""
    points = _points()
    old = [LinearityPoint(p.label, p.peak_m_s2, 1.1 * p.sensitivity, p.u, p.expanded, DC_GAIN) for p in points[:2]]
    fit, note = campaign_linearity(old + points[2:])
    assert fit is not None and fit.n == 2 and fit.slope_rel_per_m_s2 == pytest.approx(C, rel=1e-9)
    assert "2 shot(s) without a quasi-static gain" in note and "s001-r1, s002-r1" in note
    assert fitted_points(old + points[2:]) == points[2:]
    fit, note = campaign_linearity([LinearityPoint(p.label, p.peak_m_s2, p.sensitivity, p.u, p.expanded, DC_GAIN)
                                    for p in points])
    assert fit is not None and fit.n == 4 and "DC gain" in note
    assert all(p.kind == STATIC_GAIN for p in points)
