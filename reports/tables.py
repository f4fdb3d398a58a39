"""The report's tables as text rows (label, value) or (header, rows), shared by the PDF pages
and the HTML: one shot's results, its pole analysis and DCM design, and a campaign's per-shot
figures and spread."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from hopkinson.analysis.response import natural_frequency_damping
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.reports.data import (
    G_M_S2,
    QUANTITIES,
    ShotEntry,
    figures_of_merit,
    identification_dict,
    truth_comparison,
)
from hopkinson.reports.statistics import CampaignStatistics


def fmt(value: Any, scale: float = 1.0, digits: int = 4) -> str:
    if value is None:
        return "—"
    if isinstance(value, str):
        return value
    try:
        x = float(value) / scale
    except (TypeError, ValueError):
        return str(value)
    if not math.isfinite(x):
        return "—"
    if 10 ** digits <= abs(x) < 1e9:
        return f"{x:.0f}"  # 29980, not 2.998e+04
    return f"{x:.{digits}g}"


def unit_suffix(unit: str) -> str:
    return f" ({unit})" if unit else ""


def results_rows(entry: ShotEntry) -> list[tuple[str, str]]:
    """The key results of one shot as (label, text) rows."""
    a = entry.analysis
    if a is None:
        return [("analysis", entry.error or "no analysis")]
    f = figures_of_merit(entry)
    ident = identification_dict(a)
    rows = [
        ("model order", f"{a.model.order} ({ident.get('order_selection', 'knee')})"),
        ("main mode f_n", f"{fmt(f['natural_frequency_hz'], 1e3, 5)} kHz"),
        ("main mode damping ζ", fmt(f["damping_ratio"], digits=4)),
        ("FBSD ±5 %", f"{fmt(f['fbsd_5_hz'], 1e3)} kHz"),
        ("FBSD ±10 %", f"{fmt(f['fbsd_10_hz'], 1e3)} kHz"),
        ("fit (measured vs model)", f"{fmt(f['fit_percent'], digits=5)} %"),
        ("peak acceleration", f"{fmt(f['peak_acceleration_m_s2'])} m/s² ({fmt(f['peak_acceleration_m_s2'], G_M_S2)} g)"),
        ("pulse width (10 % of peak)", f"{fmt(f['pulse_width_s'], 1e-6)} µs"),
    ]
    if f["shock_sensitivity"] is not None:
        text = f"{fmt(f['shock_sensitivity'], digits=5)} × nominal"
        if f["sensitivity_v_per_m_s2"] is not None:
            text += (f" = {fmt(f['sensitivity_v_per_m_s2'], digits=5)} V/(m/s²)"
                     f" = {fmt(f['sensitivity_v_per_m_s2'] * G_M_S2 * 1e3, digits=5)} mV/g")
        rows.append(("shock sensitivity S_sh (ISO 16063-13)", text))
    design = a.dcm.design or {}
    rows += [
        ("DCM ratio r, damping ζ_e", f"{fmt(design.get('ratio'))}, {fmt(design.get('damping'))}"),
        ("FBSD ±5 % / ±10 % with DCM",
         f"{fmt(a.compensated_fbsd_hz.get('5'), 1e3)} / {fmt(a.compensated_fbsd_hz.get('10'), 1e3)} kHz"),
        ("rise-time ratio (10–90 %, without ÷ with DCM)", fmt(a.rise_time_ratio)),
        ("settling-time ratio (±5 %, without ÷ with DCM)", fmt(a.settling_time_ratio)),
    ]
    cmp = truth_comparison(entry)
    if cmp is not None:
        rows.append(("simulated truth f_n, ζ", f"{fmt(cmp['truth_natural_frequency_hz'], 1e3, 5)} kHz, "
                                               f"{fmt(cmp['truth_damping_ratio'])}: pole error "
                                               f"{cmp['pole_error_percent']:.3f} %"))
    for w in a.warnings:
        rows.append(("warning", w))
    return rows


def pole_rows(analysis: ShotAnalysis) -> tuple[list[str], list[list[str]]]:
    """Table 1 of the paper for the model: pole, |p|, f_n, ζ, T'_r (samples), ratio r_i."""
    header = ["pole p_i", "|p_i|", "f_n (kHz)", "ζ", "T'_r (samples)", "r_i"]
    rows = []
    dt = analysis.model.sample_interval_s
    for item in analysis.pole_analysis:
        p = complex(*item["pole"])
        if p != 0:
            fn, zeta = natural_frequency_damping(np.array([p]), dt)
            fn_text, z_text = fmt(fn[0], 1e3, 5), fmt(zeta[0])
        else:
            fn_text = z_text = "—"
        rows.append([f"{p.real:.5f} {'+' if p.imag >= 0 else '−'} {abs(p.imag):.5f}j", f"{abs(p):.5f}",
                     fn_text, z_text, fmt(item["response_time_samples"], digits=5), fmt(item.get("ratio"))])
    return header, rows


def dcm_rows(analysis: ShotAnalysis) -> list[tuple[str, str]]:
    d = analysis.dcm

    def zlist(values: np.ndarray) -> str:
        return ", ".join(f"{v.real:.4f}{v.imag:+.4f}j" for v in values) or "—"

    design = d.design or {}
    return [
        ("zeros (= model poles)", zlist(d.zeros)),
        ("poles (designed)", zlist(d.poles)),
        ("gain K (unit DC gain)", fmt(d.gain, digits=6)),
        ("ratio r / damping ζ_e", f"{fmt(design.get('ratio'))} / {fmt(design.get('damping'))}"),
        ("sample interval", f"{fmt(d.sample_interval_s, 1e-6)} µs"),
    ]


def spread_rows(stats: CampaignStatistics) -> tuple[list[str], list[list[str]]]:
    header = ["quantity", "n", "mean", "std", "CV (%)", "min", "max"]
    rows = []
    for key, label, unit, scale in QUANTITIES:
        s = stats.spread[key]
        rows.append([label + unit_suffix(unit), str(s["n"]), fmt(s["mean"], scale, 5), fmt(s["std"], scale, 3),
                     fmt(s["cv_percent"], digits=3), fmt(s["min"], scale, 5), fmt(s["max"], scale, 5)])
    return header, rows


def per_shot_rows(entries: Sequence[ShotEntry]) -> tuple[list[str], list[list[str]]]:
    header = ["shot", "state", "p (bar)", "peak (g)", "δ (µs)", "n", "f_n (kHz)", "ζ",
              "FBSD ±5 % (kHz)", "FBSD ±10 % (kHz)", "S_sh", "fit (%)"]
    rows = []
    for e in entries:
        f = figures_of_merit(e)
        rows.append([e.label, e.state or ("analysed" if e.analysis else "—"), fmt(e.pressure_bar, digits=3),
                     fmt(f["peak_acceleration_m_s2"], G_M_S2, 4), fmt(f["pulse_width_s"], 1e-6, 3),
                     fmt(f["order"]), fmt(f["natural_frequency_hz"], 1e3, 5), fmt(f["damping_ratio"], digits=3),
                     fmt(f["fbsd_5_hz"], 1e3), fmt(f["fbsd_10_hz"], 1e3), fmt(f["shock_sensitivity"], digits=4),
                     fmt(f["fit_percent"], digits=4)])
    return header, rows
