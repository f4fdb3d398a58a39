"""The report's tables as text rows (label, value) or (header, rows), shared by the PDF pages
and the HTML: one shot's results (value ± U, k ≈ 2, where the shot has its uncertainty), its
measurement uncertainty and budget, its compensation check, its pole analysis and DCM design;
a campaign's per-shot figures, spread and combined key figures. Every figure comes from the
shot's KeyFigures (analysis.key_figures) or its CompensationCheck, never recomputed."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.analysis.response import natural_frequency_damping
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.analysis.sine_comparison import SineComparison
from hopkinson.reports.data import (
    G_M_S2,
    QUANTITIES,
    ShotEntry,
    figures_of_merit,
    truth_comparison,
)
from hopkinson.reports.statistics import COMBINED, CampaignStatistics


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


def sig(value: Any, scale: float = 1.0, digits: int = 2) -> str:
    """`value` / scale to `digits` significant digits in plain notation, trailing zeros kept
    (an uncertainty 0.0030 stays 0.0030, a std 4.5e-05 reads 0.000045); as `fmt` otherwise."""
    if value is None or isinstance(value, str):
        return fmt(value, scale, digits)
    x = float(value) / scale
    if not math.isfinite(x) or x == 0:
        return fmt(value, scale, digits)
    decimals = digits - 1 - math.floor(math.log10(abs(x)))
    if decimals <= 0:
        return f"{round(x, decimals):.0f}"
    text = f"{x:.{decimals}f}"
    if abs(float(text)) >= 10 ** (digits - decimals):  # rounding carried a digit up: 0.00996 -> 0.010
        text = f"{x:.{decimals - 1}f}"
    return text


BUDGET_NEGLIGIBLE = 1e-3  # a source below 1/1000 of its column's largest u reads "≈ 0", not 3.9e-09


def unit_suffix(unit: str) -> str:
    return f" ({unit})" if unit else ""


NOT_RECOMMENDED = "compensation does not improve this shot"


VOLT_PREFIXES = ((1.0, "V"), (1e-3, "mV"), (1e-6, "µV"), (1e-9, "nV"))


def volt_scale(value: float) -> tuple[float, str]:
    """The largest of V, mV, µV, nV in which |value| (volts) reads at least 0.1: (scale, unit)."""
    for scale, unit in VOLT_PREFIXES:
        if abs(value) / scale >= 0.1:
            return scale, unit
    return VOLT_PREFIXES[-1]


def nominal_sensitivity_text(v_per_m_s2: float) -> str:
    """A nominal sensitivity in V/(m/s²) and V/g, SI-prefixed: '0.2 µV/(m/s²) = 1.961 µV/g'."""
    parts = []
    for value, per in ((v_per_m_s2, "(m/s²)"), (v_per_m_s2 * G_M_S2, "g")):
        scale, unit = volt_scale(value)
        parts.append(f"{value / scale:.4g} {unit}/{per}")
    return " = ".join(parts)


def sensitivity_text(figure: Figure | None, kf: KeyFigures, nominal_v_per_m_s2: float | None) -> str:
    """A sensitivity (response units per m/s²) as value ± U, with V/(m/s²) and V/g (SI-prefixed:
    0.2000 ± 0.0011 µV/(m/s²), not 0.0000002000) when the response was scaled by a nominal
    sensitivity ("× nominal")."""
    if figure is None or figure.value is None:
        return "—"
    if kf.response_unit != "m/s^2":
        return f"{figure.format(digits=5)} {kf.response_unit}/(m/s²)"
    text = f"{figure.format(digits=5)} × nominal"
    if nominal_v_per_m_s2:
        for factor, per in ((nominal_v_per_m_s2, "(m/s²)"), (nominal_v_per_m_s2 * G_M_S2, "g")):
            volts = Figure(figure.value * factor, None,
                           None if figure.interval is None else (figure.interval[0] * factor,
                                                                 figure.interval[1] * factor))
            scale, unit = volt_scale(factor)  # the nominal's prefix: 0.1 µV nominal -> 0.09998 µV, not 99.98 nV
            text += f" = {volts.format(scale, digits=5)} {unit}/{per}"
    return text


def figure_text(figure: Figure | None, scale: float = 1.0, unit: str = "", digits: int = 4) -> str:
    """value ± U (k ≈ 2) in `unit`, or the value alone; "—" when unknown; "not determined: why"."""
    if figure is not None and figure.not_determined:
        return f"not determined: {figure.not_determined}"
    if figure is None or figure.value is None:
        return "—"
    if figure.expanded is None:
        return fmt(figure.value, scale, digits) + (f" {unit}" if unit else "")
    return figure.format(scale, digits, unit)


# The results' sensitivity row: the model's DC gain as the mean of both directions (compression and
# tension, analysis.input_terms), the sensitivity every page and certificate reports.
SENSITIVITY_ROW = "sensitivity (model DC gain, mean of both directions)"


def results_rows(entry: ShotEntry) -> list[tuple[str, str]]:
    """The key results of one shot as (label, text) rows (value ± U where it has its uncertainty)."""
    a, kf = entry.analysis, entry.key_figures
    if a is None or kf is None:
        return [("analysis", entry.error or "no analysis")]
    peak = kf.peak_acceleration_m_s2
    if not kf.is_result:
        return [("analysis", kf.not_a_result_reason)]
    rows = [
        ("model order", f"{kf.order} ({kf.order_how})"),
        (SENSITIVITY_ROW,
         figure_text(kf.sensitivity) if kf.sensitivity.not_determined else
         sensitivity_text(kf.sensitivity, kf, entry.nominal_sensitivity_v_per_m_s2)),
        *asymmetry_rows(entry.stored),
        ("main mode f_n", figure_text(kf.natural_frequency_hz, 1e3, "kHz", 5)),
        ("main mode damping ζ", figure_text(kf.damping_ratio)),
        ("FBSD ±5 %", kf.fbsd_text("5")),
        ("FBSD ±10 %", kf.fbsd_text("10")),
        ("fit (measured vs model)", f"{fmt(kf.fit_percent, digits=5)} %"),
        *sine_joint_rows(entry.stored.get("identification") or {}),
        ("peak acceleration", f"{figure_text(peak, 1e3, 'km/s²')} ({figure_text(peak, G_M_S2, 'g')})"
         if peak is not None else "—"),
        ("pulse width (10 % of peak)", figure_text(kf.pulse_width_s, 1e-6, "µs")),
    ]
    if kf.shock_sensitivity is not None:
        rows.append(("shock sensitivity S_sh (ISO 16063-13)",
                     sensitivity_text(kf.shock_sensitivity, kf, entry.nominal_sensitivity_v_per_m_s2)))
    elif "shock_sensitivity" in kf.not_determined:
        rows.append(("shock sensitivity S_sh (ISO 16063-13)", kf.not_determined["shock_sensitivity"]))
    design = a.dcm.design or {}
    comp = kf.compensated_fbsd_hz
    rows += [
        ("DCM ratio r, damping ζ_e", f"{fmt(design.get('ratio'))}, {fmt(design.get('damping'))}"),
        ("FBSD ±5 % / ±10 % with DCM", f"{sig(comp.get('5'), 1e3, 4)} / {sig(comp.get('10'), 1e3, 4)} kHz"),
        ("rise-time ratio (10–90 %, without ÷ with DCM)", fmt(a.rise_time_ratio)),
        ("settling-time ratio (±5 %, without ÷ with DCM)", fmt(a.settling_time_ratio)),
    ]
    check = entry.compensation
    if check is not None and check.recommended is False:  # (the compensation check says it either way)
        rows.append(("DCM", f"NOT RECOMMENDED: {check.not_recommended_reason or NOT_RECOMMENDED}"))
    cmp = truth_comparison(entry)
    if cmp is not None:
        rows.append(("simulated truth f_n, ζ", f"{fmt(cmp['truth_natural_frequency_hz'], 1e3, 5)} kHz, "
                                               f"{fmt(cmp['truth_damping_ratio'])}: pole error "
                                               f"{cmp['pole_error_percent']:.3f} %"))
    for w in check.other_warnings(kf.warnings) if check is not None else kf.warnings:
        rows.append(("warning", w))
    if entry.verdict is not None:  # first: what the technician does next
        rows.insert(0, ("verdict", entry.verdict.line()))
    return rows


def asymmetry_rows(results: dict[str, Any]) -> list[tuple[str, str]]:
    """The tension/compression asymmetry ε (analysis.input_terms): the sensitivity in the other
    direction ÷ the one reported, less one, with its U; or why it was not measured."""
    estimate = ((results.get("uncertainty") or {}).get("input_terms") or {}).get("asymmetry")
    terms = (results.get("identification") or {}).get("input_terms") or {}
    label = "asymmetry ε (other direction ÷ main − 1)"
    if estimate:
        return [(label, figure_text(Figure.of(estimate)))]
    if isinstance(terms.get("asymmetry"), float):
        return [(label, fmt(terms["asymmetry"]))]
    why = (terms.get("not_fitted") or {}).get("asymmetry")
    return [(label, f"not measured: {why}")] if why else []


def sine_joint_rows(identification: dict[str, Any]) -> list[tuple[str, str]]:
    """A model fitted with a sine calibration too (analysis.sine_joint): their consistency."""
    joint = identification.get("sine_joint")
    if not joint:
        return []
    e_n = [v for v in joint.get("e_n") or [] if v is not None]
    ratio = f"{fmt(joint.get('gain_ratio'), digits=5)}"
    if joint.get("gain_ratio_u") is not None:
        ratio += f" (u {sig(joint['gain_ratio_u'])})"
    return [
        ("fitted with the sine calibration", f"{joint.get('source')}: {joint.get('verdict')}"),
        ("sine points: largest E_n, points with E_n > 1",
         f"{fmt(max(e_n) if e_n else None, digits=3)}, {joint.get('points_beyond_e_n_1')} of {len(e_n)}"),
        ("sine level ÷ shock model level", ratio),
    ]


# (label, unit, scale, KeyFigures field) of the uncertainty table, in order
UNCERTAIN: tuple[tuple[str, str, float, str], ...] = (
    ("sensitivity (model DC gain)", "", 1.0, "sensitivity"),
    ("shock sensitivity S_sh", "", 1.0, "shock_sensitivity"),
    ("main mode f_n", "kHz", 1e3, "natural_frequency_hz"),
    ("main mode damping ζ", "", 1.0, "damping_ratio"),
    ("FBSD ±5 %", "kHz", 1e3, "5"),
    ("FBSD ±10 %", "kHz", 1e3, "10"),
    ("peak acceleration", "km/s²", 1e3, "peak_acceleration_m_s2"),
    ("pulse width", "µs", 1e-6, "pulse_width_s"),
)


def uncertainty_rows(entry: ShotEntry) -> tuple[list[str], list[list[str]]]:
    """The measurement uncertainty table: value, u, U (k ≈ 2), the 95 % coverage interval and
    the relative standard uncertainty of each key figure that carries one (empty without)."""
    header = ["quantity", "value", "standard uncertainty u", "U (k ≈ 2)", "95 % coverage interval", "u (relative)"]
    kf = entry.key_figures
    if kf is None or not kf.has_uncertainty:
        return header, []
    rows = []
    for label, unit, scale, attr in UNCERTAIN:
        figure = kf.fbsd_hz.get(attr) if attr in ("5", "10") else getattr(kf, attr)
        if figure is None or figure.value is None or figure.u is None:
            continue
        if attr in kf.fbsd_bounds:
            rows.append([label + unit_suffix(unit), kf.fbsd_text(attr), "—", "—", "—", "—"])
            continue
        rows.append([label + unit_suffix(unit if unit else ("× nominal" if attr.endswith("sensitivity") and
                                                          kf.response_unit == "m/s^2" else ""))]
                    + uncertainty_cells(figure, scale))
    check = entry.compensation
    if check is not None and check.compensated_peak is not None and check.compensated_peak.u is not None:
        rows.append(["compensated peak (km/s²)"] + uncertainty_cells(check.compensated_peak, 1e3))
    return header, rows


def uncertainty_cells(figure: Figure, scale: float) -> list[str]:
    """value, u, U, [interval], u_rel: u and U to two significant digits, the value and the
    interval to the decimals of U (GUM 7.2.6)."""
    big = figure.expanded

    def fixed(x: float | None) -> str:
        return to_decimals_of(x, big, scale)

    lo, hi = figure.interval if figure.interval is not None else (None, None)
    return [fixed(figure.value), sig(figure.u, scale), sig(big, scale), f"[{fixed(lo)}, {fixed(hi)}]",
            f"{sig(100 * figure.u_rel)} %" if figure.u_rel is not None else "—"]


def to_decimals_of(value: float | None, expanded: float | None, scale: float = 1.0) -> str:
    """`value` / scale to the decimals that show `expanded` / scale to two significant digits
    (GUM 7.2.6); as `fmt` without an expanded uncertainty."""
    if value is None:
        return "—"
    if not expanded or expanded <= 0 or not math.isfinite(expanded):
        return fmt(value, scale)
    decimals = max(0, 1 - math.floor(math.log10(expanded / scale)))
    return f"{value / scale:.{decimals}f}"


def uncertainty_method(entry: ShotEntry) -> str:
    """One sentence: how the uncertainty was evaluated (or why there is none)."""
    kf = entry.key_figures
    if kf is None:
        return ""
    if not kf.has_uncertainty:
        return "No uncertainty was evaluated for this shot (analysed without it, or it failed: see the warnings)."
    p = kf.coverage_probability or 0.95
    method = (kf.uncertainty_method or "Monte Carlo").replace("-", " ").replace("_", " ")
    method = "Monte Carlo" if method.lower() == "monte carlo" else method
    method += "" if "GUM" in method else " after GUM Supplement 1"
    return (f"Method: {method}, {kf.draws or '—'} draws. "
            f"u is the standard uncertainty, the interval the {100 * p:.0f} % coverage interval of the draws, "
            f"U its half-width (k ≈ 2); the value is the figure reported everywhere else.")


# The budget's columns: (results key in u_rel_by_figure, header, the KeyFigures figure's name)
BUDGET_FIGURES: tuple[tuple[str, str, str], ...] = (
    ("dc_gain", "sensitivity", "sensitivity"),
    ("shock_sensitivity", "S_sh", "shock_sensitivity"),
    ("natural_frequency_hz", "f_n", "natural_frequency_hz"),
    ("damping_ratio", "ζ", "damping_ratio"),
    ("fbsd_5_hz", "FBSD ±5 %", "5"),
    ("fbsd_10_hz", "FBSD ±10 %", "10"),
    ("peak_acceleration_m_s2", "peak acc.", "peak_acceleration_m_s2"),
)
BUDGET_NOTE = ("Relative standard uncertainty (%) of each figure from each source alone (the GUM's linear "
               "propagation); the last row is each figure's own u from the Monte Carlo, all sources together. "
               "Type A: evaluated from the record (its noise, the fit's scatter; '(fitted)': a correction applied to "
               "the record, the tension/compression asymmetry, the bar's motion after the pulse, the onset's "
               "disturbances, and its estimate's uncertainty). Type B: from other knowledge (the reference chain's "
               "certificates, the stated transverse sensitivity and asymmetry bound, and bounds, rectangular, on how "
               "the corrections and the model are made).")


def budget_rows(entry: ShotEntry) -> tuple[list[str], list[list[str]]]:
    """The uncertainty budget: each source's relative standard uncertainty (%) of each figure
    (the results' `u_rel_by_figure`; a budget with only `u_rel` gives the sensitivity's), the
    largest source of the sensitivity first; the last row the Monte Carlo's u of each figure."""
    kf = entry.key_figures
    if kf is None or not kf.budget:
        return ["source", "sensitivity"], []
    items = sorted(kf.budget, key=lambda b: -(_budget_share(b, "dc_gain") or 0.0))
    columns = [c for c in BUDGET_FIGURES if any(_budget_share(b, c[0]) is not None for b in items)
               and _reported(kf, c[2])]  # no column for a figure the shot does not report (an S_sh without S_sh)
    kinds = any("kind" in b for b in items)  # older results name no kind: no such column
    header = ["source"] + (["type"] if kinds else []) + [label for _key, label, _attr in columns]

    def pct(value: float | None, largest: float = 0.0) -> str:
        if value is None:
            return "—"
        if 0 < abs(value) < BUDGET_NEGLIGIBLE * largest:
            return "≈ 0"
        return sig(100 * value)

    combined: list[float | None] = []
    for _key, _label, attr in columns:
        figure = kf.fbsd_hz.get(attr) if attr in ("5", "10") else getattr(kf, attr)
        combined.append(figure.u_rel if figure is not None and attr not in kf.fbsd_bounds else None)
    largest = [max([abs(v) for v in [total] + [_budget_share(b, key) for b in items] if v is not None], default=0.0)
               for (key, _l, _a), total in zip(columns, combined, strict=True)]
    rows = [[str(b.get("source", "—"))] + ([str(b.get("kind", "—")).replace("Type ", "")] if kinds else [])
            + [pct(_budget_share(b, key), top) for (key, _l, _a), top in zip(columns, largest, strict=True)]
            for b in items]
    rows.append(["all sources (Monte Carlo)"] + ([""] if kinds else []) + [pct(total) for total in combined])
    return header, rows


def _reported(kf: KeyFigures, attr: str) -> bool:
    """Whether the shot reports the figure (a KeyFigures field, or an FBSD level key)."""
    figure = kf.fbsd_hz.get(attr) if attr in ("5", "10") else getattr(kf, attr)
    return figure is not None and figure.value is not None


def _budget_share(item: dict[str, Any], key: str) -> float | None:
    """A budget item's relative standard uncertainty of one figure (None when not given)."""
    by_figure = item.get("u_rel_by_figure")
    value = by_figure.get(key) if isinstance(by_figure, dict) else (item.get("u_rel") if key == "dc_gain" else None)
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) \
        else None


def compensation_rows(entry: ShotEntry) -> list[tuple[str, str]]:
    """The DCM's check on the shot itself: errors before and with compensation, the
    compensated band, the noise gain and band limit, the widening, the latency, the verdict."""
    check, kf = entry.compensation, entry.key_figures
    if check is None or kf is None:
        return []
    rows = []
    if check.recommended is not None:
        rows.append(("verdict", "DCM recommended" if check.recommended else
                     f"DCM NOT RECOMMENDED: {check.not_recommended_reason or NOT_RECOMMENDED}"))

    def before_after(pair: tuple[float | None, float | None] | None) -> str:
        if pair is None:
            return "—"
        return f"{fmt(pair[0], digits=3)} % → {fmt(pair[1], digits=3)} %"

    rows.append(("RMS error over the pulse (of the peak), without → with DCM", before_after(check.rms_error_pct)))
    rows.append(("peak error, without → with DCM", before_after(check.peak_error_pct)))
    comp = kf.compensated_fbsd_hz
    rows.append(("compensated FBSD ±5 % / ±10 % (model)", f"{sig(comp.get('5'), 1e3, 4)} / {sig(comp.get('10'), 1e3, 4)} kHz"))
    if check.target_widening is not None or check.reached_widening is not None:
        aimed = "no target" if check.target_widening is None else f"aimed ×{fmt(check.target_widening, digits=3)}"
        text = f"{aimed}, reached ×{fmt(check.reached_widening, digits=3)}"
        if check.widening_note:
            text += f" ({check.widening_note})"
        rows.append(("widening of the ±5 % band", text))
    if check.noise_gain is not None:
        rows.append(("noise gain (RMS, white noise)", f"{fmt(check.noise_gain, digits=3)}"
                     + (f" (limit {fmt(check.noise_gain_limit, digits=3)})" if check.noise_gain_limit else "")))
    if check.band_limit_hz is not None:
        rows.append(("band limit of the compensation (linear-phase low-pass, 4th-order Butterworth magnitude)",
                     f"{fmt(check.band_limit_hz, 1e3)} kHz (−3 dB)"))
    if check.latency_s is not None:
        rows.append(("latency removed (channel delay + DCM group delay)", f"{fmt(check.latency_s, 1e-6)} µs"))
    if check.compensated_peak is not None and check.compensated_peak.value is not None:
        rows.append(("compensated peak", figure_text(check.compensated_peak, 1e3, "km/s²")))
    return rows


def combined_rows(stats: CampaignStatistics) -> tuple[list[str], list[list[str]]]:
    """The campaign's key figures: mean of the shots, repeatability s, ū, u_c, ν, k and U."""
    header = ["quantity", "n", "mean", "repeatability s", "ū (shots)", "u_c", "ν_eff", "k", "U (95 %)"]
    rows = []
    for key, label, unit, scale, _attr in COMBINED:
        c = stats.combined.get(key)
        if c is None or c.n == 0:
            continue
        dof = ("∞" if c.dof is not None and math.isinf(c.dof) else "> 1000" if c.dof is not None and c.dof > 1000
               else fmt(c.dof, digits=2))
        n_text = str(c.n) + (f" (+{c.excluded_bounds} bound)" if c.excluded_bounds else "")
        rows.append([label + unit_suffix(unit), n_text, to_decimals_of(c.mean, c.expanded, scale),
                     sig(c.repeatability, scale),
                     sig(c.u_shots, scale), sig(c.u_combined, scale), dof, sig(c.k, digits=3),
                     sig(c.expanded, scale)])
    return header, rows


def pole_rows(analysis: ShotAnalysis) -> tuple[list[str], list[list[str]]]:
    """Table 1 of the paper for the model: pole, |p|, f_n, ζ, T'_r (samples), ratio r_i."""
    header = ["pole p_i", "|p_i|", "f_n (kHz)", "ζ", "T'_r (samples)", "r_i"]
    rows = []
    dt = analysis.model.sample_interval_s
    for item in analysis.pole_analysis:
        p = complex(*item["pole"])
        if p != 0:
            fn, zeta = natural_frequency_damping(np.array([p]), dt)
            fn_text, z_text = sig(fn[0], 1e3, 5), sig(zeta[0], digits=4)  # 33.000 and 0.03000, not 33 and 0.03
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
        std = s["std"] if s["std"] else None  # the mean, min and max to the decimals of the std

        def fixed(x: float | None, std: float | None = std, scale: float = scale) -> str:
            return to_decimals_of(x, std, scale) if std else fmt(x, scale, 5)

        rows.append([label + unit_suffix(unit), str(s["n"]), fixed(s["mean"]), sig(s["std"], scale),
                     sig(s["cv_percent"]), fixed(s["min"]), fixed(s["max"])])
    return header, rows


def per_shot_rows(entries: Sequence[ShotEntry]) -> tuple[list[str], list[list[str]]]:
    header = ["shot", "state", "p (bar)", "peak (g)", "δ (µs)", "n", "f_n (kHz)", "ζ",
              "FBSD ±5 % (kHz)", "FBSD ±10 % (kHz)", "S_sh", "fit (%)"]
    rows = []
    for e in entries:
        f = figures_of_merit(e)
        rows.append([e.label, e.state or ("analysed" if e.analysis else "—"), fmt(e.pressure_bar, digits=3),
                     fmt(f["peak_acceleration_m_s2"], G_M_S2, 4), sig(f["pulse_width_s"], 1e-6, 3),
                     fmt(f["order"]), sig(f["natural_frequency_hz"], 1e3, 5), sig(f["damping_ratio"], digits=3),
                     sig(f["fbsd_5_hz"], 1e3, 4), sig(f["fbsd_10_hz"], 1e3, 4), sig(f["shock_sensitivity"], digits=4),
                     sig(f["fit_percent"], digits=4)])
    return header, rows


SINE_CHECK_HZ = (10e3, 20e3)  # where a lab's sine calibrators stop (ISO 16063-11/-21)


def sine_rows(comparisons: Sequence[tuple[str, SineComparison]]) -> tuple[list[str], list[list[str]]]:
    """Per shot: the model's largest magnitude error against the sine points (all, and up to 10
    and 20 kHz), the delay its phase error amounts to, and the ±5 % band of sine × DCM."""
    header = ["shot", "max |error|\n(%)", "≤ 10 kHz\n(%)", "≤ 20 kHz\n(%)", "phase as a\ndelay (µs)",
              "sine × DCM\n±5 % (kHz)", "within\n2u"]
    rows = []
    for label, c in comparisons:
        band = (c.compensated_fbsd_hz or {}).get("5")
        if c.compensated_magnitude is None:
            band_text = "—"
        elif band is None:
            band_text = f"> {c.frequency_hz[-1] / 1e3:.3g} (last point)"
        else:
            band_text = fmt(band, 1e3)
        within = "—" if c.consistent is None else f"{int(np.sum(c.consistent))} of {c.consistent.size}"
        rows.append([label, fmt(c.max_magnitude_error_pct, digits=3)]
                    + [fmt(c.max_magnitude_error_below_pct(f), digits=3) for f in SINE_CHECK_HZ]
                    + [fmt(c.phase_delay_s, 1e-6, 3), band_text, within])
    return header, rows
