"""The results strip: the shot's key figures (analysis.key_figures) as the panel shows them,
value ± U where the shot carries its uncertainty, and the DCM's check with its verdict."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hopkinson.analysis.excitation import excitation_summary
from hopkinson.drivers.sim.shock import half_sine_m_s2


def test_pulse_figures_come_from_the_excitation_without_a_reduction(qtbot):
    """A record analysed without an interferometer reduction: peak and 10 % width of the
    reference pulse, checked against the half-sine's closed form."""
    from hopkinson.analysis.key_figures import KeyFigures
    from hopkinson.ui.shot_tab import ResultsStrip

    dt, width_s, peak = 1e-7, 50e-6, 2.0e5
    t = np.arange(3000) * dt
    results = {"excitation": excitation_summary(half_sine_m_s2(t, width_s, peak, 50e-6), dt).to_dict()}
    width_10 = width_s * (1 - 2 * math.asin(0.1) / math.pi)
    kf = KeyFigures.from_results(results)
    assert kf.pulse_width_s.value == pytest.approx(width_10, rel=1e-3)
    assert kf.peak_acceleration_m_s2.value == pytest.approx(peak, rel=1e-3)
    strip = ResultsStrip()
    qtbot.addWidget(strip)
    strip.show_figures(kf)
    assert strip.values["peak"].text() == f"{peak / 1e3:.0f} km/s² ({peak / 9.80665:.0f} g)"
    assert strip.values["pulse"].text() == f"{width_10 * 1e6:.1f} µs"


def test_the_strip_shows_value_plus_minus_u_and_the_dcm_verdict(qtbot):
    from hopkinson.analysis.key_figures import KeyFigures
    from hopkinson.reports.data import CompensationCheck
    from hopkinson.ui.shot_tab import ResultsStrip

    u_fn = 108.0  # Hz: U = 1.96 u = 211.7 Hz -> two significant digits: 0.21 kHz
    results = {
        "model": {"order": 2, "dc_gain": 1.0001, "sample_interval_s": 1e-6},
        "identification": {"fit_percent": 99.65, "main_mode": {"natural_frequency_hz": 27001.3, "damping_ratio": 0.05}},
        "reduction": {"response_unit": "m/s^2", "shock_sensitivity": 1.61},
        "fbsd_hz": {"5": 5911.3, "10": 8168.5},
        "fbsd_bounds": {"10": {"lower_bound_hz": 18000.0, "reason": "unsupported by the excitation"}},
        "uncertainty": {"method": "monte-carlo", "draws": 200, "coverage_probability": 0.95,
                        "dc_gain": {"value": 1.0001, "u": 0.004, "interval": [0.99226, 1.01794]},
                        "main_mode": {"natural_frequency_hz": {"value": 27001.3, "u": u_fn,
                                                               "interval": [26789.6, 27213.0]}},
                        "fbsd_hz": {"5": {"value": 5911.3, "u": 47.3, "interval": [5818.6, 6004.0]}},
                        "budget": [{"source": "grating pitch", "u_rel": 0.0005}]},
        "dcm": {"compensated_fbsd_hz": {"5": 17730.0, "10": 21540.0}, "recommended": False,
                "not_recommended_reason": "the compensated RMS error exceeds the uncompensated one",
                "noise_gain": 3.2, "band_limit_hz": 40000.0,
                "check": {"rms_error_pct": {"uncompensated": 4.95, "compensated": 6.1},
                          "peak_error_pct": {"uncompensated": 60.7, "compensated": -0.7}}},
    }
    strip = ResultsStrip()
    qtbot.addWidget(strip)
    kf = KeyFigures.from_results(results)
    strip.show_figures(kf, CompensationCheck.of(kf))
    v = strip.values
    assert v["resonance"].text() == "27.00 ± 0.21 kHz"  # value to the decimals of U (GUM 7.2.6)
    assert v["fbsd_5"].text() == "5.911 ± 0.093 kHz"
    assert v["fbsd_10"].text() == "> 18.0 kHz" and "unsupported" in v["fbsd_10"].toolTip()
    assert v["sensitivity"].text() == "1.000 ± 0.013 × nominal"
    assert v["shock"].text() == "1.6100 × nominal"  # no uncertainty stored for it: the value alone
    assert v["comp_5"].text() == "17.73 kHz"
    assert v["check_rms"].text() == "4.95 % → 6.1 %" and v["check_peak"].text() == "60.7 % → -0.7 %"
    assert v["band_limit"].text() == "40.0 kHz" and v["noise_gain"].text() == "×3.2"
    assert not strip.verdict.isHidden()
    assert strip.verdict.text() == "DCM NOT RECOMMENDED: the compensated RMS error exceeds the uncompensated one"


def test_every_figure_of_the_strip_shows_whole_in_the_smallest_window(qtbot, make_panel, tmp_path, artifacts_dir):
    """At the panel's smallest size (1280 × 800) a long shot's figures, each with its
    uncertainty, fit their cells: "489 km/s² (49904 g), 36.0 µs" lost its unit under the next
    column when peak and width shared one cell."""
    from PySide6.QtCore import QCoreApplication

    from hopkinson.analysis.key_figures import KeyFigures
    from hopkinson.reports.data import CompensationCheck
    from hopkinson.rig.shot_verdict import judge
    from tests.ui.conftest import save_shot, unreachable_config

    def fig(value: float, u: float) -> dict:
        return {"value": value, "u": u, "interval": [value - 1.96 * u, value + 1.96 * u]}

    results = {  # the widest figures a shot of a 100 000 g sensor gives (five-digit values ± U)
        "model": {"order": 12, "dc_gain": 0.99993, "sample_interval_s": 1e-6},
        "identification": {"fit_percent": 99.871, "main_mode": {"natural_frequency_hz": 126999.91,
                                                                "damping_ratio": 0.050027},
                           "supported_band_hz": [61.04, 166_314.7]},
        "params": {"sensitivity_v_per_m_s2": 0.312e-6},  # the nominal: the sensitivity shows in its unit
        "reduction": {"response_unit": "m/s^2", "shock_sensitivity": 1.60731},
        "excitation": {"peak_m_s2": 1.23456e6, "pulse_width_s": 111.8e-6},
        "fbsd_hz": {"5": 25906.7, "10": 38162.3},
        "uncertainty": {"method": "monte-carlo", "draws": 400, "coverage_probability": 0.95,
                        "dc_gain": fig(0.99993, 0.00265), "shock_sensitivity": fig(1.60731, 0.00424),
                        "main_mode": {"natural_frequency_hz": fig(126999.91, 0.2554),
                                      "damping_ratio": fig(0.050027, 0.0000092)},
                        "fbsd_hz": {"5": fig(25906.7, 0.714), "10": fig(38162.3, 0.918)}},
        "dcm": {"compensated_fbsd_hz": {"5": 117720.0, "10": 121330.0}, "recommended": True,
                "noise_gain": 0.241, "noise_gain_limit": 4.0, "band_limit_hz": 138200.0,
                "check": {"rms_error_pct": {"uncompensated": 41.2, "compensated": 2.91},
                          "peak_error_pct": {"uncompensated": 160.7, "compensated": -12.69}}},
    }
    window = make_panel(simulate=False, connect=False, config=unreachable_config(tmp_path)).window
    strip = window.plots.strip
    kf = KeyFigures.from_results(results)
    settings = {"sensitivity_unit": "µV/(m/s²)", "sensitivity_tolerance_percent": 5.0}  # as long as any unit
    strip.show_figures(kf, CompensationCheck.of(kf), None, judge(results, settings))
    window.resize(1280, 800)
    QCoreApplication.processEvents()
    assert window.width() == 1280 and strip.isVisible()
    assert "km/s²" in strip.values["peak"].text() and "µs" in strip.values["pulse"].text()
    save_shot(window, artifacts_dir / "panel-strip-widest.png")
    for key, label in strip.values.items():
        assert label.text() != "—", key
        assert_shows_whole(label, key)
    # the simulated demo shot's figures (docs/panel.png) each on one line
    results["identification"]["main_mode"]["natural_frequency_hz"] = 26999.91
    results["uncertainty"]["main_mode"]["natural_frequency_hz"] = fig(26999.91, 0.23)
    results["excitation"]["peak_m_s2"] = 4.894e5
    results["dcm"]["check"]["peak_error_pct"]["uncompensated"] = 60.7
    kf = KeyFigures.from_results(results)
    strip.show_figures(kf, CompensationCheck.of(kf), None, judge(results, settings))
    QCoreApplication.processEvents()
    for key, label in strip.values.items():
        assert_shows_whole(label, key, one_line=True)


def assert_shows_whole(label, key: str, one_line: bool = False) -> None:
    """The label's text, wrapped at spaces as the label wraps it, fits the label's rectangle
    (`one_line`: without wrapping)."""
    from PySide6.QtCore import QRect, Qt

    room = label.contentsRect()
    flags = int(Qt.AlignmentFlag.AlignLeft) | (int(Qt.TextFlag.TextWordWrap) if label.wordWrap() else 0)
    need = label.fontMetrics().boundingRect(QRect(0, 0, room.width(), 10_000), flags, label.text())
    assert need.width() <= room.width() and need.height() <= room.height(), \
        f"{key}: {label.text()!r} needs {need.width()} × {need.height()} px, has {room.width()} × {room.height()}"
    if one_line:
        assert need.height() <= label.fontMetrics().lineSpacing() + 1, f"{key}: {label.text()!r} wraps"


def test_log_axes_are_labelled_in_plain_numbers(qtbot):
    """The magnitude plots' kHz axis read "1, 10¹, 10²" (pyqtgraph's mixed labels) and the
    vacuum axis "10¹, 10², 10³ mbar": plain numbers throughout."""
    from hopkinson.ui.plots import LiveTrend, MagnitudePlot

    plot, trend = MagnitudePlot("m", "model", "with DCM"), LiveTrend()
    for widget in (plot, trend):
        qtbot.addWidget(widget)
    f_hz = np.geomspace(50.0, 5e5, 200)
    plot.show_curves(f_hz, 1 / np.abs(1 - (f_hz / 27e3) ** 2 + 0.1j * f_hz / 27e3), None, {"5": 5.9e3})
    assert plot.peak_note.toPlainText().startswith("peak ×")  # above the scale: said in words,
    assert plot.peak_note.fill.color().alpha() > 200  # on a white ground the curve does not cross out
    axis = plot.getAxis("bottom")
    assert axis.logMode
    assert axis.tickStrings([-1.0, 0.0, 1.0, 2.0, np.log10(20.0)], 1.0, 1.0) == ["0.1", "1", "10", "100", "20"]
    vacuum = trend.getPlotItem().getAxis("right")
    assert vacuum.logMode and vacuum.tickStrings([1.0, 2.0, 3.0], 1.0, 1.0) == ["10", "100", "1000"]


def test_the_strip_says_the_dcm_verdict_once(qtbot):
    from hopkinson.analysis.key_figures import KeyFigures
    from hopkinson.reports.data import CompensationCheck
    from hopkinson.ui.shot_tab import ResultsStrip

    reason = "nothing to compensate: no pole of the model is one the shot supports"
    results = {"model": {"order": 2, "dc_gain": 1.0, "sample_interval_s": 1e-6},
               "warnings": [f"DCM: the band widening {reason}", f"DCM not recommended for this shot: {reason}",
                            "the pulse excites the sensor's resonance"],
               "dcm": {"recommended": False, "not_recommended_reason": reason, "noise_gain": 0.2}}
    strip = ResultsStrip()
    qtbot.addWidget(strip)
    kf = KeyFigures.from_results(results)
    strip.show_figures(kf, CompensationCheck.of(kf))
    assert strip.verdict.text() == f"DCM NOT RECOMMENDED: {reason}"
    assert strip.warnings.text() == "⚠ the pulse excites the sensor's resonance"


def test_the_model_magnitude_is_shown_with_its_95_percent_band(qtbot, artifacts_dir):
    """Issue 17: the model's response carries its own 95 % band (analysis.uncertainty.
    response_band), shaded under the model's curve and named in the legend; a shot without one
    shows none."""
    from hopkinson.ui.plots import MagnitudePlot, configure_pyqtgraph
    from tests.ui.conftest import save_shot

    configure_pyqtgraph()  # the panel's white ground
    plot = MagnitudePlot("Magnitude |H(f)/H(0)|", "identified model", "with DCM")
    qtbot.addWidget(plot)
    plot.resize(700, 420)
    f_hz = np.geomspace(100.0, 4.9e5, 600)
    model = np.abs(1 / (1 - (f_hz / 52e3) ** 2 + 0.02j * f_hz / 52e3))
    band_f = np.geomspace(100.0, 56e3, 160)
    centre = np.abs(1 / (1 - (band_f / 52e3) ** 2 + 0.02j * band_f / 52e3))
    half = 0.02 + 0.25 * (band_f / 56e3) ** 2  # widening towards the band's top
    band = {"frequency_hz": list(band_f), "coverage_probability": 0.95, "magnitude_rel": list(centre),
            "magnitude_rel_low": list(centre * (1 - half)), "magnitude_rel_high": list(centre * (1 + half))}
    plot.show_curves(f_hz, model, None, {"5": 11.4e3, "10": 15.5e3}, band)
    plot.show()
    qtbot.waitExposed(plot)
    low, high = plot.band_low.getData(), plot.band_high.getData()
    assert np.allclose(high[1] - low[1], 2 * half * centre)  # the band as given, around the model
    legend = [label.text for _item, label in plot.getPlotItem().legend.items]
    assert "95 % band" in legend
    image = save_shot(plot, artifacts_dir / "panel-magnitude-band.png")
    # shaded: the band's blue tint fills the plot between its edges where the model is near 1
    from PySide6.QtGui import QImage

    picture = QImage(str(image))
    vb = plot.getPlotItem().getViewBox()
    at = float(np.interp(25e3, band_f, centre * (1 + half / 2)))  # between the model's curve and the band's top
    inside = plot.mapFromScene(vb.mapViewToScene(pg_point(np.log10(25.0), at)))
    colour = picture.pixelColor(inside.x(), inside.y())
    assert colour.blue() > colour.red() + 20, colour.name()  # tinted blue, not the white ground
    plot.show_curves(f_hz, model, None, {"5": 11.4e3}, None)
    assert plot.band_low.getData()[0] is None or len(plot.band_low.getData()[0]) == 0
    assert "95 % band" not in [label.text for _item, label in plot.getPlotItem().legend.items]


def pg_point(x: float, y: float):
    from PySide6.QtCore import QPointF

    return QPointF(x, y)
