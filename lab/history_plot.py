"""A sensor's history drawn for people (matplotlib, no pyplot): each key figure against the
calibration date with its U as error bars; the panel's tab draws the same with pyqtgraph."""

from __future__ import annotations

from datetime import datetime

import matplotlib.dates as mdates
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hopkinson.lab.history import SensorHistory

# key, label, display scale, unit: the figures a history shows (lab.schema.FIGURE_KEYS' headline ones)
SHOWN = (("sensitivity", "sensitivity", 1.0, ""), ("shock_sensitivity", "shock sensitivity", 1.0, ""),
         ("natural_frequency_hz", "f_n", 1e3, "kHz"), ("fbsd_5_hz", "FBSD ±5 %", 1e3, "kHz"))


def history_series(history: SensorHistory, key: str, scale: float, simulated: bool | None = None
                   ) -> tuple[list[datetime], list[float], list[float]]:
    """(dates, values, U) of one figure over the calibrations that have it (U 0 when unknown);
    `simulated` True or False keeps only the simulated or the real calibrations."""
    dates, values, expanded = [], [], []
    for c in history.calibrations:
        if simulated is not None and c.simulated != simulated:
            continue
        figure = c.figures.get(key)
        if figure is None or figure.value is None:
            continue
        dates.append(datetime.fromisoformat(c.utc_time.replace("Z", "+00:00")))
        values.append(figure.value / scale)
        expanded.append((figure.expanded or 0.0) / scale)
    return dates, values, expanded


def history_figure(history: SensorHistory) -> Figure:
    fig = Figure(figsize=(8.27, 9.0), layout="constrained")
    FigureCanvasAgg(fig)
    s = history.sensor
    flags = "; ".join(history.flags) or "no flags"
    fig.suptitle(f"{s.serial} ({s.model or 'model unknown'}): {len(history.calibrations)} calibrations — {flags}",
                 fontsize=10)
    axes = fig.subplots(len(SHOWN), 1, sharex=True)
    for ax, (key, label, scale, unit) in zip(axes, SHOWN, strict=True):
        dates, values, expanded = history_series(history, key, scale, simulated=False)
        ax.errorbar(dates, values, yerr=expanded, fmt="o", ms=3, capsize=2)
        dates, values, expanded = history_series(history, key, scale, simulated=True)
        if dates:  # simulated calibrations: open red markers, never judged
            ax.errorbar(dates, values, yerr=expanded, fmt="o", ms=4, capsize=2, mfc="none", color="#c00",
                        label="simulated")
            ax.legend(fontsize=7, loc="best")
        ax.set_ylabel(f"{label} ({unit})" if unit else label, fontsize=8)
        drift = history.drift.get(key)
        if drift is not None and drift.e_n is not None:
            ax.set_title(f"E_n = {drift.e_n:+.2f}" + (" — drifted" if drift.drifted else ""), fontsize=8,
                         loc="right", color="#a00" if drift.drifted else "#333")
        ax.grid(alpha=0.3)
        ax.ticklabel_format(axis="y", useOffset=False)
    locator = mdates.AutoDateLocator()
    axes[-1].xaxis.set_major_locator(locator)
    axes[-1].xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    axes[-1].set_xlabel("calibration date (UTC)")
    return fig
