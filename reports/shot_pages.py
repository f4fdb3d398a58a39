"""The pages of one shot (matplotlib figures, A4 portrait).

Excitation and identification (pulse, spectrum, loss by order with the chosen order, AIC/BIC,
measured vs model response); the model (magnitude with the ±5 %/±10 % bands and the FBSD
marked, phase); poles (z-plane map and the Table-1 pole analysis); the DCM (compensated
magnitude and FBSD, step responses, design). A shot without an analysis gets one page saying why.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from hopkinson.analysis.dcm_figures import step_responses as dcm_step_responses
from hopkinson.analysis.excitation import amplitude_spectrum, pulse_width, pulse_window
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.response import (
    frequency_response,
    nyquist_hz,
    response_times_samples,
)
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.reports.data import (
    G_M_S2,
    ShotEntry,
    excitation_dict,
    identification_dict,
    model_delay_samples,
    prepared,
)
from hopkinson.reports.layout import (
    TABLE_WIDTH_PT,
    plain_log_ticks,
    plot_page,
    table_in_axes,
    wrap_cells,
    wrap_to_width,
)
from hopkinson.reports.tables import compensation_rows, dcm_rows, fmt, pole_rows

BAND_LEVELS = (("5", 0.05, "tab:green"), ("10", 0.10, "tab:orange"))
DCM_TABLE_COLUMNS = (0.36, 0.64)  # the DCM page's table: label, value


def excitation_page(entry: ShotEntry) -> Figure:
    """Pulse (reference, response, model), its spectrum with the band covered, loss by order, AIC/BIC."""
    a = entry.analysis
    assert a is not None
    fig = plot_page(f"{entry.label}: excitation and identification")
    grid = fig.add_gridspec(3, 2)
    ax_t = fig.add_subplot(grid[0, :])
    ax_f = fig.add_subplot(grid[1, :])
    ax_l = fig.add_subplot(grid[2, 0])
    ax_c = fig.add_subplot(grid[2, 1])
    exc = excitation_dict(a)
    ident = identification_dict(a)
    kf = entry.key_figures
    fn = kf.natural_frequency_hz.value if kf is not None and kf.natural_frequency_hz is not None else None

    rec = a.record
    if rec is not None:
        shot = prepared(a)
        u, y, y_hat = shot.reference, shot.response, shot.model_response(a)
        delay = float(a.model.delay_samples or 0.0) if shot.windowed else float(model_delay_samples(a))
        t_us = shot.time_s * 1e6
        ax_t.plot(t_us, u / 1e3, color="0.2", lw=1.2, label="reference (laser interferometer)")
        ax_t.plot(t_us, y / 1e3, color="tab:blue", lw=1.0,
                  label=("accelerometer response" if shot.windowed else
                         f"accelerometer response (shifted by its delay, {delay:.0f} samples)"))
        ax_t.plot(t_us, y_hat / 1e3, color="tab:red", lw=1.0, ls="--",
                  label=f"model response (fit {fmt(ident.get('fit_percent'), digits=4)} %"
                        + (f", input delay {delay:.2f} samples)" if shot.windowed else ")"))
        width = float(exc.get("pulse_width_s") or 0.0)
        t_peak = float(exc.get("peak_time_s") or 0.0)
        if width > 0:
            lo = (t_peak - 3 * width) * 1e6
            hi = (t_peak + 8 * width) * 1e6
            ax_t.set_xlim(max(lo, t_us[0]), min(hi, t_us[-1]))
        ax_t.legend(fontsize=7, loc="upper right")
    else:
        ax_t.text(0.5, 0.5, "record not stored", ha="center", transform=ax_t.transAxes)
    ax_t.set_xlabel("time (µs)")
    # km/s² as the results, the panel's plot and strip give it, with g on the right
    ax_t.set_ylabel("acceleration (km/s²)")
    ax_g = ax_t.secondary_yaxis("right", functions=(lambda k: k * 1e3 / G_M_S2, lambda g: g * G_M_S2 / 1e3))
    ax_g.set_ylabel("(g)")
    ax_t.set_title(f"Shock pulse: peak {fmt(exc.get('peak_m_s2'), 1e3)} km/s² ({fmt(exc.get('peak_m_s2'), G_M_S2)} g),"
                   f" width {fmt(exc.get('pulse_width_s'), 1e-6)} µs at 10 % of peak", fontsize=9)
    ax_t.grid(alpha=0.3)

    if rec is not None:
        ref = np.asarray(rec.reference, dtype=float)
        pulse = pulse_width(ref, rec.sample_interval_s, rec.start_time_s)
        seg = ref[pulse_window(pulse, ref.size, rec.sample_interval_s, rec.start_time_s)]
        f_hz, mag = amplitude_spectrum(seg, rec.sample_interval_s)
        keep = f_hz <= min(nyquist_hz(a.model), 8.0 * max(float(exc.get("band_high_hz") or 0.0), 1.0))
        norm = mag / np.max(mag)
        ax_f.plot(f_hz[keep] / 1e3, 20 * np.log10(np.maximum(norm[keep], 1e-6)), color="0.2",
                  label="|F(f)| / max (reference pulse)")
        ax_f.axhline(-3.0, color="0.5", ls=":", lw=0.8)
        lo_hz, hi_hz = float(exc.get("band_low_hz") or 0.0), float(exc.get("band_high_hz") or 0.0)
        ax_f.axvspan(lo_hz / 1e3, hi_hz / 1e3, color="tab:green", alpha=0.15,
                     label=f"band covered (−3 dB): {fmt(lo_hz, 1e3)}–{fmt(hi_hz, 1e3)} kHz")
        if kf is not None and kf.supported_band_hz is not None:
            ax_f.axvline(kf.supported_band_hz[1] / 1e3, color="tab:green", ls="--", lw=1.2,
                         label=f"band the excitation supports: up to {fmt(kf.supported_band_hz[1], 1e3)} kHz")
        rule = exc.get("paper_rule_max_natural_frequency_hz")
        if rule:
            ax_f.axvline(rule / 1e3, color="tab:purple", ls="--", lw=1,
                         label=f"paper's rule f_n ≤ 1.06/δ = {fmt(rule, 1e3)} kHz")
        if fn:
            ax_f.axvline(fn / 1e3, color="tab:red", lw=1, label=f"identified f_n = {fmt(fn, 1e3)} kHz")
        ax_f.set_ylim(-60, 3)
        ax_f.legend(fontsize=7, loc="upper right")
    ax_f.set_xlabel("frequency (kHz)")
    ax_f.set_ylabel("amplitude spectrum (dB)")
    ax_f.set_title("Excitation spectrum", fontsize=9)
    ax_f.grid(alpha=0.3)

    losses = ident.get("loss_by_order") or []
    arx = ident.get("arx_loss_by_order") or []
    orders = np.arange(1, len(losses) + 1)
    chosen = a.model.order

    def arr(values: list[Any]) -> np.ndarray:
        return np.array([np.nan if v is None else float(v) for v in values], dtype=float)

    if losses:
        ax_l.semilogy(orders, arr(losses), "o-", color="tab:blue", ms=4, label="bias-corrected (output error)")
    if arx:
        ax_l.semilogy(np.arange(1, len(arx) + 1), arr(arx), "s--", color="0.5", ms=3, label="plain least squares")
    ax_l.axvline(chosen, color="tab:red", lw=1.2, label=f"chosen order {chosen}")
    ax_l.set_xlabel("model order n")
    ax_l.set_ylabel("loss (as the identification reports it)")
    ax_l.set_title("Loss by order", fontsize=9)
    ax_l.legend(fontsize=6.5)
    ax_l.grid(alpha=0.3)

    # Each criterion above its own minimum, on a log scale: order 1 is often orders of magnitude
    # worse, and a linear axis would hide the knee.
    for values, marker, colour, name in ((ident.get("aic_by_order") or [], "o-", "tab:blue", "AIC"),
                                         (ident.get("bic_by_order") or [], "s-", "tab:orange", "BIC")):
        y = arr(values)
        if y.size and np.any(np.isfinite(y)):
            ax_c.semilogy(np.arange(1, y.size + 1), y - np.nanmin(y) + 1.0, marker, ms=3, color=colour, label=name)
    ax_c.axvline(chosen, color="tab:red", lw=1.2, label=f"chosen order {chosen}")
    ax_c.set_xlabel("model order n")
    ax_c.set_ylabel("criterion − its minimum + 1")
    ax_c.set_title("AIC / BIC (on the bias-corrected loss)", fontsize=9)
    ax_c.legend(fontsize=6.5)
    ax_c.grid(alpha=0.3)
    return fig


def frequency_grid(model: DiscreteModel, points: int = 1200) -> np.ndarray:
    nyq = nyquist_hz(model)
    return np.logspace(np.log10(nyq / 1e4), np.log10(nyq * 0.999), points)


def normalised(h: np.ndarray, dc: float) -> np.ndarray:
    return np.abs(h) / abs(dc)


def draw_bands(ax: Any, fbsd: dict[str, float], label_prefix: str = "FBSD", linestyle: str = "--",
           shade: bool = True, bounds: dict[str, Any] | None = None,
           intervals: dict[str, tuple[float, float] | None] | None = None) -> None:
    """The ±5 %/±10 % bands (shaded) and the FBSD edges with their 95 % intervals (when known);
    an edge the shot reports only as a bound (KeyFigures.fbsd_bounds) says so in its label."""
    for key, level, colour in BAND_LEVELS:
        if shade:
            ax.axhspan(1 - level, 1 + level, color=colour, alpha=0.08 if key == "10" else 0.12,
                       label=f"±{key} % band")
        f = fbsd.get(key)
        if f:
            label = f"{label_prefix} ±{key} % = {fmt(f, 1e3)} kHz"
            bound = (bounds or {}).get(key)
            if bound is not None:
                label += f": the shot supports only > {fmt(bound.lower_bound_hz, 1e3)} kHz"
            ax.axvline(f / 1e3, color=colour, ls=linestyle, lw=1.3, label=label)
            interval = (intervals or {}).get(key)
            if interval is not None:
                ax.axvspan(interval[0] / 1e3, interval[1] / 1e3, color=colour, alpha=0.25, lw=0,
                           label=f"95 % interval of FBSD ±{key} %")


def model_page(entry: ShotEntry) -> Figure:
    """Magnitude (full range in dB; normalised around the bands with the FBSD) and phase."""
    a = entry.analysis
    assert a is not None
    model = a.model
    fig = plot_page(f"{entry.label}: identified model, frequency response")
    ax_db, ax_band, ax_ph = fig.subplots(3, 1, height_ratios=[1.0, 1.2, 0.9])
    f = frequency_grid(model)
    h = frequency_response(model, f)
    dc = model.dc_gain
    mag = normalised(h, dc)
    ax_db.semilogx(f / 1e3, 20 * np.log10(mag), color="tab:blue", label=f"model (order {model.order})")
    for key, level, colour in BAND_LEVELS:
        ax_db.axhspan(20 * np.log10(1 - level), 20 * np.log10(1 + level), color=colour, alpha=0.2,
                      label=f"±{key} % band")
    kf = entry.key_figures
    if kf is not None and kf.natural_frequency_hz is not None and kf.natural_frequency_hz.value:
        zeta = kf.damping_ratio.format() if kf.damping_ratio is not None else "—"
        ax_db.axvline(kf.natural_frequency_hz.value / 1e3, color="tab:red", lw=0.8, ls=":",
                      label=f"f_n = {kf.natural_frequency_hz.format(1e3, unit='kHz')}, ζ = {zeta}")
    ax_db.set_xlabel("frequency (kHz)")
    ax_db.set_ylabel("|H(f)/H(0)| (dB)")
    ax_db.set_title("Normalised magnitude, DC to Nyquist", fontsize=9)
    ax_db.grid(alpha=0.3)
    ax_db.legend(fontsize=7)

    f10 = a.fbsd_hz.get("10") or nyquist_hz(model) / 10
    fl = np.linspace(0.0, min(nyquist_hz(model), 2.5 * f10), 800)
    ml = normalised(frequency_response(model, fl), dc)
    ax_band.plot(fl / 1e3, ml, color="tab:blue", lw=1.5, label="model")
    band = (entry.stored.get("uncertainty") or {}).get("response_band")
    if band:  # the model's response with its 95 % band, from the same Monte Carlo draws as the figures
        band_hz = np.asarray(band["frequency_hz"], dtype=float)
        label = f"{100 * band.get('coverage_probability', 0.95):.0f} % band of the model (Monte Carlo)"
        ax_band.fill_between(band_hz / 1e3, band["magnitude_rel_low"], band["magnitude_rel_high"], color="tab:blue",
                             alpha=0.25, lw=0, label=label)
    draw_bands(ax_band, a.fbsd_hz, bounds=kf.fbsd_bounds if kf is not None else None,
               intervals={k: f.interval for k, f in kf.fbsd_hz.items()} if kf is not None else None)
    ax_band.set_ylim(0.8, 1.2)
    ax_band.set_xlim(0, fl[-1] / 1e3)
    ax_band.set_xlabel("frequency (kHz)")
    ax_band.set_ylabel("|H(f)/H(0)| (ratio)")
    ax_band.set_title("Band of small distortion: first frequency where the gain leaves 1 ± 5 % / 1 ± 10 %",
                      fontsize=9)
    ax_band.grid(alpha=0.3)
    ax_band.legend(fontsize=7, loc="lower left")

    phase = np.degrees(np.unwrap(np.angle(h)))
    ax_ph.semilogx(f / 1e3, phase, color="tab:purple")
    if band:  # the band's phase includes the fitted delay; this page's does not: the band about this curve
        at = np.degrees(np.unwrap(np.angle(frequency_response(model, band_hz))))
        centre = np.asarray(band["phase_deg"], dtype=float)
        ax_ph.fill_between(band_hz / 1e3, at + np.asarray(band["phase_low_deg"]) - centre,
                           at + np.asarray(band["phase_high_deg"]) - centre, color="tab:purple", alpha=0.25, lw=0,
                           label=f"{100 * band.get('coverage_probability', 0.95):.0f} % band")
    for key, _level, colour in BAND_LEVELS:
        fb = a.fbsd_hz.get(key)
        if fb:
            ax_ph.axvline(fb / 1e3, color=colour, ls="--", lw=1.0, label=f"FBSD ±{key} %")
    ax_ph.set_xlabel("frequency (kHz)")
    ax_ph.set_ylabel("phase (degrees)")
    ax_ph.set_title("Phase (input delay not included)", fontsize=9)
    ax_ph.grid(alpha=0.3)
    ax_ph.legend(fontsize=7)
    for ax in (ax_db, ax_ph):
        plain_log_ticks(ax)
    return fig


def _z_plane(ax: Any, a: ShotAnalysis, xlim: tuple[float, float], ylim: tuple[float, float],
             legend: bool) -> None:
    theta = np.linspace(0, 2 * np.pi, 720)
    ax.plot(np.cos(theta), np.sin(theta), color="0.6", lw=0.8, label="unit circle")
    poles, zeros, dp = a.model.poles, a.model.zeros, a.dcm.poles

    def inside(v: np.ndarray) -> np.ndarray:
        return v[(v.real >= xlim[0]) & (v.real <= xlim[1]) & (v.imag >= ylim[0]) & (v.imag <= ylim[1])]

    shown = inside(zeros) if zeros.size else zeros
    off = int(zeros.size - shown.size)
    ax.plot(poles.real, poles.imag, "x", color="tab:blue", ms=9, mew=2, label="model poles")
    if zeros.size:
        ax.plot(shown.real, shown.imag, "o", mfc="none", color="tab:blue", ms=8,
                label="model zeros" + (f" ({off} outside this view)" if off else ""))
    ax.plot(dp.real, dp.imag, "+", color="tab:red", ms=10, mew=2, label="DCM poles (designed)")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.axhline(0, color="0.85", lw=0.6)
    ax.axvline(0, color="0.85", lw=0.6)
    ax.set_xlabel("Re z")
    ax.set_ylabel("Im z")
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=6.5, loc="upper left")


def poles_page(entry: ShotEntry) -> Figure:
    """z-plane map of the model's poles and zeros and the DCM's poles (whole and near z = 1);
    the Table-1 pole analysis."""
    a = entry.analysis
    assert a is not None
    fig = plot_page(f"{entry.label}: poles and zeros")
    grid = fig.add_gridspec(2, 2, height_ratios=[1.4, 0.8])
    ax_z = fig.add_subplot(grid[0, 0])
    ax_zoom = fig.add_subplot(grid[0, 1])
    ax_tab = fig.add_subplot(grid[1, :])
    _z_plane(ax_z, a, (-1.3, 1.3), (-1.3, 1.3), legend=True)
    ax_z.set_title(f"z-plane (sample interval {fmt(a.model.sample_interval_s, 1e-6)} µs)", fontsize=9)
    near = np.concatenate([a.model.poles, a.dcm.poles])
    near = near[np.abs(near) > 0.5]
    if near.size:
        half = max(float(np.max(np.abs(near - 1.0))) * 1.15, 0.05)
        _z_plane(ax_zoom, a, (1.0 - half, 1.0 + half * 0.3), (-half, half), legend=False)
    ax_zoom.set_title("near z = 1 (the slow poles)", fontsize=9)
    header, rows = pole_rows(a)
    table_in_axes(ax_tab, header, rows, fontsize=8, col_widths=[0.3, 0.13, 0.14, 0.12, 0.17, 0.14])
    ax_tab.set_title("Pole analysis (the paper's Table 1): response time T'_r = −3/ln|p| samples, "
                     "ratio r_i = T'_r(slowest)/T'_r", loc="left", fontsize=9)
    return fig


def step_responses(analysis: ShotAnalysis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(time_s, model step response, model followed by the DCM), both normalised to 1 at DC."""
    model, dcm = analysis.model, analysis.dcm
    slowest = float(np.max(response_times_samples(np.concatenate([model.poles, dcm.poles]))))
    alone, both = dcm_step_responses(model, dcm, int(min(max(1.5 * slowest, 64), 20_000)))
    return np.arange(alone.size) * model.sample_interval_s, alone, both


def dcm_page(entry: ShotEntry) -> Figure:
    """The DCM: magnitudes (model, DCM, compensated) with both FBSDs, step responses, design."""
    a = entry.analysis
    assert a is not None
    model, dcm = a.model, a.dcm
    fig = plot_page(f"{entry.label}: dynamic compensation model (DCM)")
    check = entry.compensation
    rows = wrap_cells(dcm_rows(a) + compensation_rows(entry)[1:], DCM_TABLE_COLUMNS, TABLE_WIDTH_PT, 7.5)
    lines = sum(max(r[0].count("\n"), r[1].count("\n")) + 1 for r in rows)
    ax_m, ax_s, ax_tab = fig.subplots(3, 1, height_ratios=[1.3, 1.0, 0.15 + 0.075 * lines])
    comp = a.compensated_fbsd_hz
    top = max(comp.get("10") or 0.0, a.fbsd_hz.get("10") or 0.0)
    if check is not None and check.band_limit_hz:  # the band limit in view too
        top = max(top, check.band_limit_hz / 1.4)
    f = np.linspace(0.0, min(nyquist_hz(model), 1.6 * top if top else nyquist_hz(model)), 1000)
    h = frequency_response(model, f)
    g = dcm.frequency_response(f)
    ax_m.plot(f / 1e3, normalised(h, model.dc_gain), color="tab:blue", lw=1.2, label="model H")
    ax_m.plot(f / 1e3, np.abs(g) / abs(dcm.dc_gain), color="0.5", lw=1.0, ls=":", label="DCM G")
    ax_m.plot(f / 1e3, normalised(h * g, model.dc_gain * dcm.dc_gain), color="tab:red", lw=1.6,
              label="compensated H·G")
    draw_bands(ax_m, a.fbsd_hz, "FBSD", ":", shade=True)
    draw_bands(ax_m, comp, "compensated FBSD", "-", shade=False)
    ax_m.set_ylim(0.5, 1.5)
    ax_m.set_xlim(0, f[-1] / 1e3)
    ax_m.set_xlabel("frequency (kHz)")
    ax_m.set_ylabel("|H(f)/H(0)| (ratio)")
    if check is not None and check.band_limit_hz:
        ax_m.axvline(check.band_limit_hz / 1e3, color="tab:purple", lw=1.2, ls="-.",
                     label=f"band limit of the compensation {fmt(check.band_limit_hz, 1e3)} kHz")
    if check is not None and check.recommended is False:
        reason = check.not_recommended_reason or "compensation does not improve this shot"
        width_pt = 0.85 * fig.get_figwidth() * 72.0
        ax_m.set_title("\n".join(wrap_to_width(f"DCM NOT RECOMMENDED: {reason}", 9.0, width_pt, bold=True)),
                       fontsize=9, color="#a00000", fontweight="bold")
    else:
        ax_m.set_title("Compensated response: the DCM widens the band of small distortion", fontsize=9)
    ax_m.legend(fontsize=6.5, loc="upper left", ncol=2)
    ax_m.grid(alpha=0.3)

    t, alone, both = step_responses(a)
    ax_s.plot(t * 1e6, alone, color="tab:blue", label="model (uncompensated)")
    ax_s.plot(t * 1e6, both, color="tab:red", label=f"with DCM (without ÷ with: rise time {fmt(a.rise_time_ratio, digits=3)}, "
                f"±5 % settling {fmt(a.settling_time_ratio, digits=3)})")
    for level in (0.1, 0.9):
        ax_s.axhline(level, color="0.6", lw=0.6, ls=":")
    ax_s.axhline(1.0, color="0.3", lw=0.6)
    ax_s.set_xlabel("time (µs)")
    ax_s.set_ylabel("step response (normalised)")
    ax_s.set_title("Step responses (10 % and 90 % marked)", fontsize=9)
    ax_s.legend(fontsize=7)
    ax_s.grid(alpha=0.3)
    table_in_axes(ax_tab, None, rows, fontsize=7.5, col_widths=list(DCM_TABLE_COLUMNS), line_heights=True)
    ax_tab.set_title("DCM design (Eqs. 13–25) and its check on this shot", loc="left", fontsize=9)
    return fig


def failed_shot_page(entry: ShotEntry) -> Figure:
    fig = plot_page(f"{entry.label}: no analysis")
    ax = fig.subplots(1, 1)
    rows = [[k, v] for k, v in entry.identity.items()]
    rows.append(["state", entry.state or "—"])
    rows.append(["analysis", entry.error or "no analysis stored"])
    table_in_axes(ax, None, rows, col_widths=[0.3, 0.7], width_pt=TABLE_WIDTH_PT)
    return fig


def shot_pages(entry: ShotEntry) -> list[tuple[str, Figure]]:
    """(caption, figure) of every page of one shot."""
    if entry.analysis is None:
        return [(f"{entry.label}: no analysis", failed_shot_page(entry))]
    return [
        (f"{entry.label}: excitation and identification", excitation_page(entry)),
        (f"{entry.label}: model frequency response, FBSD", model_page(entry)),
        (f"{entry.label}: poles and zeros", poles_page(entry)),
        (f"{entry.label}: dynamic compensation model", dcm_page(entry)),
    ]
