"""Every page of a report in order: the summary (title page), the campaign pages, each shot's.

The summary page holds the identity of the accelerometer and the rig and either the shot's key
results (a section per sensor when the shot recorded a second one) or (a campaign) the per-shot table, the spread and the cross-validation summary; it is
laid out by `layout.TextPages`, so it continues on a second page rather than run off the first.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from hopkinson.reports.campaign_pages import (
    LINEARITY_CAPTION,
    campaign_responses_page,
    cross_validation_page,
    linearity_page,
    sine_page,
)
from hopkinson.reports.data import CalibrationReport, ShotEntry
from hopkinson.reports.layout import TextPages, freeze_layout, new_figure
from hopkinson.reports.shot_pages import shot_pages
from hopkinson.reports.statistics import (
    COMBINATION_NOTE,
    CampaignStatistics,
    campaign_statistics,
    linearity_sensitivity,
)
from hopkinson.reports.tables import (
    BUDGET_NOTE,
    budget_rows,
    combined_rows,
    compensation_rows,
    per_shot_rows,
    results_rows,
    sine_rows,
    spread_rows,
    uncertainty_method,
    uncertainty_rows,
)

SUBTITLE = ("Hopkinson-bar shock calibration: dynamic model, band of small distortion (FBSD) and dynamic "
            "compensation model (DCM)")
SUMMARY = "Summary"
SINE_CAPTION = "Campaign: the shock models against the sinusoidal calibration"


def title_pages(report: CalibrationReport, stats: CampaignStatistics | None) -> list[Figure]:
    """The summary: identity, then the key results (one shot) or the campaign's tables."""
    first = new_figure()

    def continued(fig: Figure) -> float:
        fig.text(0.5, 1.0 - 30.0 / (fig.get_figheight() * 72.0), f"{report.title} (continued)", ha="center",
                 va="top", fontsize=9, color="0.3", parse_math=False)
        return 52.0

    page = TextPages(first, continued=continued)
    page.centred(report.title, 13.0)
    page.centred(SUBTITLE, 9.0, bold=False)
    page.heading("Accelerometer, rig and campaign" if report.campaign else "Accelerometer and rig")
    page.table(None, [list(row) for row in report.identity.items()], widths=[0.3, 0.7])
    if report.campaign and stats is not None:
        page.heading("Shots")
        page.table(*per_shot_rows(report.shots), size=7.0)
        page.paragraph("δ: pulse width at 10 % of peak; n: model order; S_sh: shock sensitivity (× nominal, "
                       "ISO 16063-13); fit: measured vs model response", size=6.5)
        page.heading(f"Spread across {len(stats.labels)} analysed shots (standard deviation with n − 1)")
        page.table(*spread_rows(stats), size=7.5)
        header, rows = combined_rows(stats)
        if rows:
            page.heading("Key figures of the campaign: mean of the shots with its expanded uncertainty")
            page.table(header, rows, size=7.5, widths=[3.0, 0.4, 1.0, 1.4, 0.9, 0.9, 0.8, 0.5, 0.9])
            page.paragraph(COMBINATION_NOTE, size=6.5, colour="0.25")
        flagged = [(e.label, e.compensation) for e in report.shots
                   if e.compensation is not None and e.compensation.recommended is False]
        if flagged:
            page.heading("DCM not recommended")
            for label, check in flagged:
                page.paragraph(f"{label}: {check.not_recommended_reason or 'compensation does not improve the shot'}",
                               colour="#a00000")
        if stats.sine:
            page.heading("Each shot's model against the sinusoidal calibration")
            page.table(*sine_rows(stats.sine), size=7.5)
        for note in stats.sine_notes:
            page.paragraph(note, colour="#a00000")
        if stats.linearity is not None:  # shots at two or more levels
            page.heading("Amplitude linearity (ISO 16063-22)")
            page.paragraph(f"{linearity_sensitivity(stats.linearity_points, short=True)} against the amplitude it is "
                           f"measured at: slope {stats.linearity.text()} (95 %; plot and table on the linearity page)")
            if stats.linearity_note:
                page.paragraph(stats.linearity_note, colour="0.25")
        text = cross_validation_summary(stats)
        if text:
            page.heading("Cross-validation (each shot's model on every other shot)")
            page.paragraph(text)
    else:  # one shot: a results section per sensor (a shot with a second sensor has two entries)
        for i, entry in enumerate(report.shots):
            sensor_results(page, entry, "" if i == 0 else entry.label)
    if report.notes:
        page.heading("Notes")
        for note in report.notes:
            page.paragraph(note)
    return page.pages


def sensor_results(page: TextPages, entry: ShotEntry, sensor: str = "") -> None:
    """One sensor's results, uncertainty and compensation check; `sensor` names a further
    sensor in the headings and shows its own identity first."""
    suffix = f": {sensor}" if sensor else ""
    page.heading(f"Results{suffix}")
    if sensor:
        page.table(None, [[k, v] for k, v in entry.identity.items() if k in ("Accelerometer", "Nominal sensitivity")],
                   widths=[0.38, 0.62])
    page.table(None, [list(row) for row in results_rows(entry)], widths=[0.38, 0.62])
    header, rows = uncertainty_rows(entry)
    if rows:
        page.heading(f"Measurement uncertainty{suffix}")
        page.table(header, rows, size=7.5)
        page.paragraph(uncertainty_method(entry), size=7.0, colour="0.25")
        header, rows = budget_rows(entry)
        if rows:
            page.heading(f"Uncertainty budget{suffix}: relative standard uncertainty (%)", size=9.5)
            page.table(header, rows, size=7.5)
            page.paragraph(BUDGET_NOTE, size=7.0, colour="0.25")
    elif entry.key_figures is not None:
        page.paragraph(uncertainty_method(entry), size=7.0, colour="0.25")
    rows = compensation_rows(entry)
    if rows:
        page.heading(f"Compensation checked on the shot itself{suffix}")
        page.table(None, [list(r) for r in rows], widths=[0.45, 0.55])


def cross_validation_summary(stats: CampaignStatistics) -> str:
    """One line: the lowest, diagonal and off-diagonal fit % of the cross-validation matrix."""
    m = stats.cross_validation_percent
    finite = m[np.isfinite(m)] if m.size else m
    if not stats.labels or not finite.size:
        return ""
    off = m[~np.eye(m.shape[0], dtype=bool)] if m.shape[0] > 1 else finite
    off = off[np.isfinite(off)]
    text = f"fit % of model i on shot j: lowest {np.min(finite):.3f} %, diagonal mean {np.nanmean(np.diag(m)):.3f} %"
    if off.size and m.shape[0] > 1:
        text += f", off-diagonal mean {np.mean(off):.3f} %"
    return text + " (matrix on the next page)"


def report_pages(report: CalibrationReport, stats: CampaignStatistics | None = None) -> list[tuple[str, Figure]]:
    """Every page of the report in order: summary, campaign pages (if any), then each shot's."""
    if report.campaign and stats is None:
        stats = campaign_statistics(report.shots, report.sine_calibration)
    summary = title_pages(report, stats)
    pages = [(SUMMARY if i == 0 else f"{SUMMARY} (continued)", fig) for i, fig in enumerate(summary)]
    if report.campaign and stats is not None and stats.labels:
        pages.append(("Campaign: cross-validation and spread", cross_validation_page(stats, report.shots)))
        pages.append(("Campaign: responses of all shots", campaign_responses_page(report.shots)))
        if stats.sine:
            pages.append((SINE_CAPTION, sine_page(stats.sine, report.sine_calibration)))
        if stats.linearity is not None:
            pages.append((LINEARITY_CAPTION, linearity_page(stats)))
    for entry in report.shots:
        pages.extend(shot_pages(entry))
    for _caption, fig in pages:
        freeze_layout(fig)
    return pages
