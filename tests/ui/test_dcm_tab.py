"""The DCM design tab: changing r (spin box or slider) updates the compensated FBSD; checked
against the closed form of a second-order sensor (with ζₑ = ζ the compensated system is the
sensor r times faster), the paper's Eq. (42) design, and the exported JSON."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from PySide6.QtCore import Qt

from hopkinson.analysis.dcm import load_dcm
from hopkinson.analysis.model import DiscreteModel
from tests.ui.conftest import dispose, save_shot

DT = 1e-6
FN_HZ, ZETA = 10_000.0, 0.05


def second_order_model(fn_hz: float, zeta: float, dt: float = DT) -> DiscreteModel:
    """Unit-DC-gain all-pole model with the poles exp(s·T) of a second-order sensor."""
    wn = 2 * np.pi * fn_hz
    s = wn * (-zeta + 1j * np.sqrt(1 - zeta**2))
    poles = np.exp(np.array([s, np.conj(s)]) * dt)
    a = np.real(np.poly(poles))
    return DiscreteModel(dt, a, [float(np.sum(a))])


def closed_form_edge_hz(fn_hz: float, zeta: float, level: float) -> float:
    """First f where |H| = 1/sqrt((1-u²)² + (2ζu)²) leaves 1 ± level (u = f/f_n); light damping
    rises first, so solve |H| = 1 + level: a quadratic in u²."""
    g = 1.0 / (1.0 + level) ** 2  # (1-v)² + 4ζ²v = g, v = u²
    b = 4 * zeta**2 - 2
    v = (-b - math.sqrt(b * b - 4 * (1 - g))) / 2
    return fn_hz * math.sqrt(v)


def hz(label) -> float:
    text = label.text()
    assert text.endswith(" kHz"), text
    return float(text.split()[0]) * 1e3


@pytest.fixture
def tab(qtbot):
    from hopkinson.ui.dcm_tab import DcmTab
    from hopkinson.ui.plots import configure_pyqtgraph

    configure_pyqtgraph()
    widget = DcmTab()
    widget.resize(1100, 650)
    widget.show()
    yield widget
    dispose(widget)


def test_ratio_change_updates_the_compensated_fbsd(qtbot, tab, artifacts_dir):
    model = second_order_model(FN_HZ, ZETA)
    tab.set_model(model, ratio=1.0, damping=ZETA)
    # r = 1 with ζₑ = ζ: the DCM cancels the poles and puts them back: nothing changes
    for key, level in (("5", 0.05), ("10", 0.10)):
        assert hz(tab.model_fbsd[key]) == pytest.approx(closed_form_edge_hz(FN_HZ, ZETA, level), rel=0.01)
        assert hz(tab.compensated_fbsd[key]) == pytest.approx(hz(tab.model_fbsd[key]), rel=0.01)

    before = tab.compensated_fbsd["5"].text()
    tab.ratio.setValue(2.0)  # as typed in the spin box
    qtbot.waitUntil(lambda: tab.compensated_fbsd["5"].text() != before, timeout=3000)
    for key, level in (("5", 0.05), ("10", 0.10)):
        assert hz(tab.compensated_fbsd[key]) == pytest.approx(closed_form_edge_hz(2 * FN_HZ, ZETA, level), rel=0.02)
        assert tab.widening[key].text() == f"×{hz(tab.compensated_fbsd[key]) / hz(tab.model_fbsd[key]):.2f}"
    lines = tab.fbsd_lines
    assert lines["5"].isVisible()
    assert lines["5"].value() == pytest.approx(math.log10(tab.compensated_fbsd_hz()["5"] / 1e3))

    # the slider drives the same control (log scale); r = 3 → three times the band
    before = tab.compensated_fbsd["5"].text()
    position = round((math.log10(3.0) + 1) / (math.log10(200.0) + 1) * 1000)
    tab.ratio_slider.setValue(position)
    qtbot.waitUntil(lambda: tab.compensated_fbsd["5"].text() != before, timeout=3000)
    r = tab.ratio.value()
    assert r == pytest.approx(3.0, rel=0.01)
    assert hz(tab.compensated_fbsd["5"]) == pytest.approx(closed_form_edge_hz(r * FN_HZ, ZETA, 0.05), rel=0.02)
    # the step response follows: the compensated one rises r times faster
    assert "faster" in tab.rise_label.text()
    save_shot(tab, artifacts_dir / "panel-dcm-tab.png")


def test_paper_design_and_an_impossible_one(qtbot, tab):
    """Table-1 poles with the Eq. (42) design (r = 12.5, ζₑ = 0.707, extra pair 0.6 ± 0.1j)."""
    poles = np.array([0.9740 + 0.1396j, 0.9740 - 0.1396j, 0.8174 + 0.0518j, 0.8174 - 0.0518j])
    a = np.real(np.poly(poles))
    model = DiscreteModel(DT, a, [float(np.sum(a))])
    tab.set_model(model, ratio=12.5, damping=0.707, extra_poles=[0.6 + 0.1j, 0.6 - 0.1j])
    assert tab.error is None
    den = np.real(np.poly(tab.design.dcm.poles))
    assert den == pytest.approx([1.0, -2.8006, 2.9581, -1.3931, 0.2469], abs=2e-4)  # Eq. (42)
    shown = tab.compensated_fbsd["5"].text()
    tab.extra.setText("0.6+0.1j, 0.6-0.1j, 0.5, 0.4")  # 6 poles for 4 zeros: refused, with the reason
    qtbot.waitUntil(lambda: tab.error is not None, timeout=3000)
    assert "at most" in tab.message.text() and not tab.export_dcm_button.isEnabled()
    assert tab.compensated_fbsd["5"].text() == shown  # the last good design stays on screen
    tab.reset_button.click()
    assert tab.error is None and tab.export_dcm_button.isEnabled()


def test_export_dcm_json_is_what_compensate_reads(qtbot, tab, tmp_path):
    model = second_order_model(FN_HZ, ZETA)
    tab.set_model(model, ratio=4.0, damping=0.707)
    path = tab.export_dcm(tmp_path / "dcm.json")
    dcm = load_dcm(path)  # the loader of `hopkinson compensate --dcm`
    assert np.allclose(np.sort_complex(dcm.poles), np.sort_complex(tab.design.dcm.poles))
    assert dcm.dc_gain == pytest.approx(1.0)
    data = json.loads(path.read_text())
    assert data["compensated_fbsd_hz"]["5"] == pytest.approx(tab.compensated_fbsd_hz()["5"])
    assert data["dcm"]["design"]["ratio"] == pytest.approx(4.0)


def test_no_model_means_no_design(qtbot, tab):
    assert tab.model is None and not tab.ratio.isEnabled() and not tab.export_dcm_button.isEnabled()
    qtbot.mouseClick(tab.reset_button, Qt.MouseButton.LeftButton)  # disabled: nothing happens
    assert tab.design is None


def test_the_shots_verdict_shows_only_for_a_dcm_not_recommended(qtbot, tab):
    model = second_order_model(FN_HZ, ZETA)
    tab.set_model(model, 3.0, 0.707, not_recommended_reason="nothing to compensate")
    assert tab.verdict.isVisible() and tab.verdict.text() == "The shot's DCM is NOT RECOMMENDED: nothing to compensate"
    tab.set_model(model, 3.0, 0.707)  # the next shot's DCM is recommended: no stale verdict
    assert not tab.verdict.isVisible() and tab.verdict.text() == ""


def test_the_panels_exports_never_write_over_a_shot_file(qtbot, tab, tmp_path):
    # issue 18: the panel's save dialogs go through the same check as the command line's -o
    from hopkinson.fileio import HDF5_SIGNATURE, UnsafeOutputError
    from hopkinson.ui.log_view import LogView

    shot = tmp_path / "shot.h5"
    shot.write_bytes(HDF5_SIGNATURE + b"\0" * 64)
    before = shot.read_bytes()
    tab.set_model(second_order_model(FN_HZ, ZETA), ratio=4.0, damping=0.707)
    with pytest.raises(UnsafeOutputError, match="HDF5 shot file"):
        tab.export_dcm(shot)
    with pytest.raises(UnsafeOutputError, match="HDF5 shot file"):
        LogView().save(shot)
    assert shot.read_bytes() == before


def test_a_design_error_after_an_export_is_red_and_in_plain_words(qtbot, tab, tmp_path):
    """After a DCM export (green), a later design error showed green with Python text: "DCM:
    DCM: … got ((0.6+0.1j),)" (issue 42)."""
    tab.set_model(second_order_model(FN_HZ, ZETA), ratio=2.0, damping=0.707)
    target = tmp_path / "dcm.json"
    tab.export_dcm(target)
    tab.say("ok", f"DCM written to {target}")
    assert tab.message_level == "ok" and "#1e6b2e" in tab.message.styleSheet()
    tab.extra.setText("0.6+0.1j")  # one pole of a pair without its conjugate
    tab.redesign()
    text = tab.message.text()
    assert tab.message_level == "error" and "#b3261e" in tab.message.styleSheet()
    assert text == "Cannot design this DCM: extra poles must be both members of every complex pair " \
                   "(0.6+0.1j has no conjugate partner)"
    assert "DCM: DCM" not in text and "got (" not in text and "extra_poles" not in text
    tab.extra.setText("")
    tab.redesign()
    assert tab.message.text() == "" and not tab.export_dcm_button.isHidden()
