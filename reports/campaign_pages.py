"""The campaign's own pages: the cross-validation matrix with the spread of f_n and S_sh
against the shock level, every shot's identified response on one plot and, when the plan names
one, every shot's model against the sensor's sinusoidal calibration."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from hopkinson.analysis.response import frequency_response, nyquist_hz
from hopkinson.analysis.sine_comparison import SineCalibration, SineComparison
from hopkinson.reports.data import G_M_S2, ShotEntry
from hopkinson.reports.layout import plain_log_ticks, plot_page, table_in_axes
from hopkinson.reports.shot_pages import BAND_LEVELS, frequency_grid, normalised
from hopkinson.reports.statistics import STATIC_GAIN, CampaignStatistics, linearity_sensitivity
from hopkinson.reports.tables import fmt, sig, sine_rows, to_decimals_of


def cross_validation_page(stats: CampaignStatistics, entries: Sequence[ShotEntry]) -> Figure:
    """The cross-validation matrix and f_n / S_sh / FBSD against the shock level."""
    fig = plot_page("Campaign: cross-validation and spread",
                  "row i: model identified on shot i; column j: simulated on shot j's reference")
    ax_cv, ax_fn, ax_s = fig.subplots(3, 1, height_ratios=[1.4, 1.0, 1.0])
    m = stats.cross_validation_percent
    labels = stats.labels
    if m.size:
        finite = m[np.isfinite(m)]
        low = float(np.min(finite)) if finite.size else 0.0
        im = ax_cv.imshow(m, cmap="viridis", vmin=min(low, 99.0), vmax=100.0)
        for i in range(m.shape[0]):
            for j in range(m.shape[1]):
                if np.isfinite(m[i, j]):  # black on the light end of the scale, white on the dark end
                    ax_cv.text(j, i, f"{m[i, j]:.2f}", ha="center", va="center", fontsize=7,
                               color="black" if luminance(im.cmap(im.norm(m[i, j]))) > 0.45 else "white")
        ax_cv.set_xticks(range(len(labels)), labels, rotation=45, ha="right", fontsize=7)
        ax_cv.set_yticks(range(len(labels)), labels, fontsize=7)
        fig.colorbar(im, ax=ax_cv, label="fit (%)", shrink=0.8)
    ax_cv.set_xlabel("shot j (reference and measured response)")
    ax_cv.set_ylabel("model of shot i")
    ax_cv.set_title("Cross-validation fit %: 100·(1 − ‖y_j − ŷ_ij‖ / ‖y_j − ȳ_j‖)", fontsize=9)

    peaks = np.array([np.nan if f["peak_acceleration_m_s2"] is None else f["peak_acceleration_m_s2"] / G_M_S2
                      for f in stats.figures])

    def series(key: str, scale: float) -> np.ndarray:
        return np.array([np.nan if f[key] is None else f[key] / scale for f in stats.figures])

    def with_spread(ax: Any, key: str, scale: float, colour: str, label: str, unit: str) -> None:
        y = series(key, scale)
        s = stats.spread[key]
        if s["mean"] is None:
            ax.text(0.5, 0.5, "not available for these shots", ha="center", va="center", transform=ax.transAxes)
            return
        ax.plot(peaks, y, "o", color=colour, label=label)
        mean = s["mean"] / scale
        std = (s["std"] or 0.0) / scale
        # the mean to the decimals of the std, both with the unit ("mean 27, ± 1 std (4.53e-05)" before)
        ax.axhline(mean, color=colour, lw=1, label=f"mean {to_decimals_of(mean, std or None)} {unit}")
        if s["std"] is not None:
            ax.axhspan(mean - std, mean + std, color=colour, alpha=0.12, label=f"± 1 std ({sig(std)} {unit})")
        # At least ±1 % of the mean in view, so a tiny spread looks tiny.
        half = max(3.0 * std, 0.01 * abs(mean), float(np.nanmax(np.abs(y - mean))) * 1.2)
        ax.set_ylim(mean - half, mean + half)
        ax.ticklabel_format(axis="y", useOffset=False)
        ax.legend(fontsize=7)

    with_spread(ax_fn, "natural_frequency_hz", 1e3, "tab:blue", "f_n per shot", "kHz")
    ax_fn.set_xlabel("peak acceleration (g)")
    ax_fn.set_ylabel("natural frequency f_n (kHz)")
    ax_fn.set_title("Main resonance against the shock level", fontsize=9)
    ax_fn.grid(alpha=0.3)
    with_spread(ax_s, "shock_sensitivity", 1.0, "tab:green", "S_sh per shot", "× nominal")
    ax_s.set_xlabel("peak acceleration (g)")
    ax_s.set_ylabel("shock sensitivity (× nominal)")
    ax_s.set_title("Shock sensitivity (ISO 16063-13) against the shock level: linearity", fontsize=9)
    ax_s.grid(alpha=0.3)
    return fig


def luminance(rgba: Sequence[float]) -> float:
    """Relative luminance (ITU-R BT.709 weights) of a colour, 0 (black) … 1 (white)."""
    r, g, b = rgba[:3]
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


def campaign_responses_page(entries: Sequence[ShotEntry]) -> Figure:
    """Every shot's normalised magnitude on one plot, with the bands and each FBSD ±5 %."""
    fig = plot_page("Campaign: identified responses of all shots")
    ax_db, ax_band = fig.subplots(2, 1)
    analysed = [e for e in entries if e.analysis is not None]
    colours = [f"C{i % 10}" for i in range(len(analysed))]
    top = 0.0
    for e, c in zip(analysed, colours, strict=True):
        a = e.analysis
        assert a is not None
        f = frequency_grid(a.model, 800)
        ax_db.semilogx(f / 1e3, 20 * np.log10(normalised(frequency_response(a.model, f), a.model.dc_gain)),
                       color=c, lw=1, label=e.label)
        top = max(top, a.fbsd_hz.get("10") or 0.0)
    for key, level, colour in BAND_LEVELS:
        ax_db.axhspan(20 * np.log10(1 - level), 20 * np.log10(1 + level), color=colour, alpha=0.2,
                      label=f"±{key} % band")
    ax_db.set_xlabel("frequency (kHz)")
    ax_db.set_ylabel("|H(f)/H(0)| (dB)")
    ax_db.set_title("Normalised magnitude of each shot's model", fontsize=9)
    ax_db.grid(alpha=0.3)
    ax_db.legend(fontsize=6.5, ncol=3)
    plain_log_ticks(ax_db)
    for e, c in zip(analysed, colours, strict=True):
        a = e.analysis
        assert a is not None
        fl = np.linspace(0.0, min(nyquist_hz(a.model), 2.5 * top if top else nyquist_hz(a.model)), 600)
        ax_band.plot(fl / 1e3, normalised(frequency_response(a.model, fl), a.model.dc_gain), color=c, lw=1,
                     label=e.label)
        f5 = a.fbsd_hz.get("5")
        if f5:
            ax_band.axvline(f5 / 1e3, color=c, ls="--", lw=0.8)
    for key, level, colour in BAND_LEVELS:
        ax_band.axhspan(1 - level, 1 + level, color=colour, alpha=0.1, label=f"±{key} % band")
    ax_band.set_ylim(0.8, 1.2)
    ax_band.set_xlabel("frequency (kHz)")
    ax_band.set_ylabel("|H(f)/H(0)| (ratio)")
    ax_band.set_title("Around the bands (dashed: each shot's FBSD ±5 %)", fontsize=9)
    ax_band.grid(alpha=0.3)
    ax_band.legend(fontsize=6.5, ncol=3, loc="lower left")
    return fig


def sine_page(comparisons: Sequence[tuple[str, SineComparison]], sine: SineCalibration) -> Figure:
    """The sine calibration's points against each shot's model (normalised magnitudes), the
    magnitude errors with the calibration's ±2u, the phase errors and the table of sine_rows."""
    fig = plot_page("Campaign: the shock models against the sinusoidal calibration",
                    f"{Path(sine.source).name}: {sine.frequency_hz.size} points, "
                    f"{fmt(sine.frequency_hz[0], 1e3)}–{fmt(sine.frequency_hz[-1], 1e3)} kHz")
    ax_m, ax_e, ax_p, ax_t = fig.subplots(4, 1, height_ratios=[1.1, 0.9, 0.7, 0.3 + 0.07 * len(comparisons)])
    first = comparisons[0][1]
    f_khz = first.frequency_hz / 1e3
    ax_m.semilogx(f_khz, first.sine_magnitude, "o", color="0.2", ms=4, label="sine calibration", zorder=5)
    for n, (label, c) in enumerate(comparisons):
        colour = f"C{n % 10}"
        ax_m.semilogx(f_khz, c.model_magnitude, "-", color=colour, lw=1, label=f"model of {label}")
        if c.compensated_magnitude is not None:
            ax_m.semilogx(f_khz, c.compensated_magnitude, "--", color=colour, lw=0.9,
                          label=f"sine × DCM of {label}")
        ax_e.semilogx(f_khz, c.magnitude_error_pct, "o-", color=colour, ms=3, lw=0.9, label=label)
        ax_p.semilogx(f_khz, c.phase_error_deg, "o-", color=colour, ms=3, lw=0.9, label=label)
    for level in (0.95, 1.05):
        ax_m.axhline(level, color="tab:green", ls=":", lw=0.8)
    if first.u_magnitude_rel is not None:
        band = 2 * 100.0 * first.u_magnitude_rel
        ax_e.fill_between(f_khz, -band, band, color="0.5", alpha=0.2,
                          label=f"±2u of the sine calibration (its {first.reference_frequency_hz:g} Hz point's u included)")
    ax_e.axhline(0.0, color="0.4", lw=0.7)
    ax_m.set_ylabel(f"|H| / |H({fmt(first.reference_frequency_hz)} Hz)|")
    ax_m.set_title("Normalised magnitude (±5 % dotted)", fontsize=9)
    ax_m.legend(fontsize=6.5, ncol=2)
    ax_e.set_ylabel("model − sine (%)")
    ax_e.set_title("Magnitude error of each shot's model", fontsize=9)
    ax_e.legend(fontsize=6.5, ncol=3)
    ax_p.set_ylabel("phase error (°)")
    ax_p.set_xlabel("frequency (kHz)")
    ax_p.set_title("Phase error (model without its channel delay)", fontsize=9)
    for ax in (ax_m, ax_e, ax_p):
        ax.grid(True, which="both", alpha=0.3)
        plain_log_ticks(ax)
    header, rows = sine_rows(comparisons)
    table_in_axes(ax_t, header, rows, fontsize=7.0, line_heights=True)
    return fig


LINEARITY_CAPTION = "Campaign: amplitude linearity"
LINEARITY_NOTE = ("ISO 16063-22: fitted to {sensitivity} (a sensitivity that means the same at every level: for "
                  "S₀(1 + c·|a|) it reads S₀(1 + c·a) at that amplitude; a peak ratio S_sh reads the resonance's "
                  "ringing when the pulse excites it, and a model's DC gain gives part of the change to the dynamics), "
                  "error bars U (95 %) of what differs from shot to shot (the reference chain and the transverse "
                  "row, common to all shots, left out: they move S₀, not c); the line "
                  "S(a) = S₀(1 + c·a) fitted with weights 1/u² (analysis.linearity); the linearity deviation is "
                  "c·(a_max − a_min), the fitted change of S over the levels covered.")


def _signed(text: str) -> str:
    """A number's text with its sign ("+0.12", "−0.3")."""
    return text if text.startswith(("-", "−")) else f"+{text}"


def linearity_page(stats: CampaignStatistics) -> Figure:
    """The sensitivity (statistics.linearity_sensitivity) against the amplitude it is measured at, with each point's U and
    the fitted line, the deviations from the line, and the table of the points."""
    fit = stats.linearity
    assert fit is not None
    points = stats.linearity_points
    fig = plot_page(LINEARITY_CAPTION, f"slope {fit.text()}")
    ax_s, ax_r, ax_t, ax_note = fig.subplots(4, 1, height_ratios=[1.2, 0.75, 0.3 + 0.075 * len(points), 0.12])
    peak_g = np.array([p.peak_m_s2 for p in points]) / G_M_S2
    s = np.array([p.sensitivity for p in points])
    big_u = np.array([np.nan if p.expanded is None else p.expanded for p in points])
    static = any(p.kind == STATIC_GAIN for p in points)
    what = "quasi-static gain" if static else "DC gain"
    abscissa = "amplitude it is measured at" if static else "amplitude Σ|a|³/Σa²"
    ax_s.errorbar(peak_g, s, yerr=np.nan_to_num(big_u), fmt="o", color="tab:green", capsize=3,
                  label=f"sensitivity ({what}) ± U per shot")
    grid = np.linspace(0.0, 1.05 * float(np.max(peak_g)), 100)
    ax_s.plot(grid, fit.sensitivity_at(grid * G_M_S2), color="0.2", lw=1,
              label=f"fit: S₀ = {to_decimals_of(fit.reference_sensitivity, fit.k * fit.u_reference_sensitivity)}, "
                    f"c = {100 * 1e5 * fit.slope_rel_per_m_s2:.3g} % per 100 km/s²")
    for sign in (-1, 1):  # the line with its slope at ±U, through the weighted centre of the points
        centre = float(np.mean(peak_g)) * G_M_S2
        slope = fit.slope_rel_per_m_s2 + sign * fit.expanded_slope_rel_per_m_s2
        base = fit.sensitivity_at(centre)
        ax_s.plot(grid, base * (1 + slope * (grid * G_M_S2 - centre)), color="0.5", lw=0.8, ls="--",
                  label="slope ± U" if sign < 0 else None)
    ax_s.set_xlabel(f"{abscissa} (g)")
    ax_s.set_ylabel(f"sensitivity, {what} (× nominal)")
    ax_s.set_title("Sensitivity against the shock level", fontsize=9)
    ax_s.grid(alpha=0.3)
    ax_s.legend(fontsize=7)
    resid = 100 * np.array(fit.residuals_rel)
    rel_u = 100 * big_u / s
    ax_r.errorbar(peak_g, resid, yerr=np.nan_to_num(rel_u), fmt="o", color="tab:green", capsize=3)
    ax_r.axhline(0.0, color="0.3", lw=0.8)
    ax_r.set_xlabel(f"{abscissa} (g)")
    ax_r.set_ylabel("sensitivity − fit (%)")
    ax_r.set_title("Deviation of each shot from the line (± U)", fontsize=9)
    ax_r.grid(alpha=0.3)
    header = ["shot", "a (g)", "a (km/s²)", "S (× nom.)", "U (95 %)", "− fit (%)"]  # S: the ylabel says which
    rows = [[p.label, f"{p.peak_m_s2 / G_M_S2:,.0f}", f"{p.peak_m_s2 / 1e3:.4g}", f"{p.sensitivity:.5g}",
             "—" if p.expanded is None else sig(p.expanded), f"{100 * r:+.2f}"]
            for p, r in zip(points, fit.residuals_rel, strict=True)]
    rows.append(["linearity", f"{fit.peak_min_m_s2 / G_M_S2:,.0f}–{fit.peak_max_m_s2 / G_M_S2:,.0f}", "",
                 f"deviation {_signed(to_decimals_of(100 * fit.deviation_rel, 100 * fit.expanded_deviation_rel))} %",
                 f"± {100 * fit.expanded_deviation_rel:.2g} %",
                 f"Birge ratio {fit.birge_ratio:.2f}" if fit.birge_ratio is not None else ""])
    table_in_axes(ax_t, header, rows, fontsize=7.0, line_heights=True)
    ax_note.axis("off")
    ax_note.text(0.0, 0.0, LINEARITY_NOTE.format(sensitivity=linearity_sensitivity(points)), fontsize=6.5, color="0.3", wrap=True, va="bottom", transform=ax_note.transAxes)
    return fig
