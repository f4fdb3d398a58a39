"""The sine-calibration comparison as a figure (`hopkinson compare-sine --plot`, the campaign
report): normalised magnitudes of the sine points, the model and the sine-measured sensor with
the DCM, the ±5 % band, and the model's magnitude and phase errors. Drawn on matplotlib's Agg
canvas (no pyplot state); written atomically through hopkinson.fileio.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hopkinson.analysis.sine_comparison import SineComparison
from hopkinson.fileio import atomic_write
from hopkinson.reports.layout import plain_log_ticks


def sine_figure(comparison: SineComparison, title: str = "") -> Figure:
    """Three panels: normalised magnitudes, magnitude error (with ±2u where known), phase error."""
    c = comparison
    f_khz = c.frequency_hz / 1e3
    fig = Figure(figsize=(8.0, 9.0), layout="constrained")
    FigureCanvasAgg(fig)
    mag, err, phase = fig.subplots(3, 1, sharex=True)
    mag.semilogx(f_khz, c.sine_magnitude, "o", color="#1f77b4", label="sine calibration")
    mag.semilogx(f_khz, c.model_magnitude, "-", color="#d62728", label="shock model")
    if c.compensated_magnitude is not None:
        mag.semilogx(f_khz, c.compensated_magnitude, "s-", color="#2ca02c", markersize=3,
                     label="sine × DCM (compensated)")
    for level in (0.95, 1.05):
        mag.axhline(level, color="grey", linestyle=":", linewidth=0.8)
    mag.set_ylabel(f"|H| / |H({c.reference_frequency_hz:g} Hz)|")
    mag.legend(loc="best", fontsize=8)
    mag.set_title(title or f"Shock model against {Path(c.source).name}")
    err.semilogx(f_khz, c.magnitude_error_pct, "o-", color="#d62728", markersize=3, label="model − sine")
    if c.u_magnitude_rel is not None:
        band = 2 * 100.0 * c.u_magnitude_rel
        err.fill_between(f_khz, -band, band, color="#1f77b4", alpha=0.2,
                         label=f"±2u of the sine calibration (its {c.reference_frequency_hz:g} Hz point's u included)")
    err.axhline(0.0, color="grey", linewidth=0.8)
    err.set_ylabel("magnitude error (%)")
    err.legend(loc="best", fontsize=8)
    phase.semilogx(f_khz, c.phase_error_deg, "o-", color="#9467bd", markersize=3)
    w = 2 * np.pi * c.frequency_hz
    phase.semilogx(f_khz, -np.degrees(w * c.phase_delay_s), ":", color="grey",
                   label=f"a delay of {c.phase_delay_s * 1e6:.3g} µs")
    phase.set_ylabel("phase error (°)")
    phase.set_xlabel("frequency (kHz)")
    phase.legend(loc="best", fontsize=8)
    for ax in (mag, err, phase):
        ax.grid(True, which="both", linewidth=0.3)
        plain_log_ticks(ax)
    return fig


def write_sine_plot(comparison: SineComparison, path: str | Path, title: str = "") -> Path:
    """Write the figure as a PNG, atomically (a failure leaves no half-written file)."""
    fig = sine_figure(comparison, title)
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=120))
