"""The panel's sensor-history tab: a serial's calibrations from the lab's record in a table and
plots, with its drift, conformity and due-date flags (a made-up history whose last calibration
drifted by a known amount)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hopkinson.lab.repository import open_repository
from tests.lab.records import made_up_record
from tests.ui.conftest import dispose, save_shot

SENSITIVITIES = (1.000, 1.001, 0.999, 1.000, 1.002, 1.001, 1.000, 1.012)  # the last one drifted


@pytest.fixture
def database(tmp_path: Path) -> str:
    url = f"sqlite:///{tmp_path / 'lab.sqlite'}"
    with open_repository(url) as repo:
        for i, s in enumerate(SENSITIVITIES):
            repo.record_shot(made_up_record("SN-42", utc=f"202{i // 4 + 4}-{i % 4 * 3 + 1:02d}-15T09:00:00Z",
                                            sensitivity=s, u=0.001, campaign=f"run-{i}"))
        repo.register_sensor("SN-42", "tester", model="ACC-60k", owner="ACME Aerospace", tolerance_percent=1.0,
                             interval_days=365)
    return url


@pytest.fixture
def tab(qtbot, database: str):
    from hopkinson.ui.plots import configure_pyqtgraph
    from hopkinson.ui.sensor_tab import SensorTab
    from hopkinson.ui.worker import Background

    configure_pyqtgraph()
    background = Background()
    widget = SensorTab(background, database, "simple")
    widget.resize(1100, 760)
    widget.show()
    yield widget
    dispose(widget)


def test_a_sensors_history_shows_its_calibrations_drift_and_flags(qtbot, tab, artifacts_dir: Path) -> None:
    tab.serial_edit.setText("SN-42")
    tab.show_button.click()
    qtbot.waitUntil(lambda: tab.history is not None, timeout=20_000)
    assert tab.table.rowCount() == len(SENSITIVITIES)
    assert tab.table.item(0, 4).text().startswith("1.0120 ± 0.0020")  # newest first
    flags = tab.flags.text()
    assert "drift in sensitivity" in flags and "overdue since 2026-10-15" in flags
    assert "FAIL: sensitivity deviates +1.20 %" in flags  # simple acceptance, tolerance ±1 %
    points = tab.plots["sensitivity"].getPlotItem().listDataItems()
    assert list(points[0].yData) == pytest.approx(SENSITIVITIES)
    save_shot(tab, artifacts_dir / "panel-sensor-history.png")


def test_an_unknown_serial_says_so(qtbot, tab) -> None:
    tab.serial_edit.setText("SN-NOPE")
    tab.show_button.click()
    qtbot.waitUntil(lambda: "not in the lab's record" in tab.summary.text(), timeout=20_000)


def test_the_sensors_tolerance_and_interval_are_set_from_the_tab(qtbot, tab) -> None:
    """Issue 42: the tolerance and the recalibration interval can be set in the panel (the lab's
    record keeps them, audited); the history is judged against them at once."""
    tab.prefill("SN-42")  # as when the tab opens on the shot's serial
    qtbot.waitUntil(lambda: tab.history is not None, timeout=20_000)
    assert tab.serial_edit.text() == "SN-42" and tab.tolerance.value() == 1.0 and tab.interval.value() == 365
    tab.tolerance.setValue(2.0)
    tab.interval.setValue(180)
    tab.owner.setText("ACME Aerospace, Test Dept.")
    tab.history = None
    tab.save_sensor_data()
    qtbot.waitUntil(lambda: tab.history is not None and "Test Dept." in tab.summary.text(), timeout=20_000)
    summary = tab.summary.text()
    assert "tolerance ±2 %" in summary and "recalibrate every 180 days" in summary
    assert "saved in the lab's record" in tab.save_message.text()
    with open_repository(tab.database_url) as repo:
        sensor = repo.sensor("SN-42")
    assert (sensor.tolerance_percent, sensor.interval_days) == (2.0, 180)
    assert "PASS" in tab.flags.text()  # +1.20 % is inside ±2 %: no longer out of tolerance
    tab.serial_edit.setText("SN-77")  # typed here by the technician: the shot's serial does not replace it
    tab.prefill("SN-99")
    assert tab.serial_edit.text() == "SN-77"


def test_the_set_up_is_checked_against_the_sensors_record(qtbot, database) -> None:
    """A serial the record knows: a nominal typed that differs from the record's is said before
    ARM (the issue's 0.312 for a 0.2 µV/(m/s²) sensor), its tolerance fills the set-up's."""
    import dataclasses

    from hopkinson.ui.shot_setup import ShotSetup
    from hopkinson.ui.worker import Background
    from tests.ui.conftest import rig_config_for_tests

    with open_repository(database) as repo:
        repo.register_sensor("SN-42", "tester", nominal_sensitivity=0.2, sensitivity_unit="µV/(m/s²)")
    config = rig_config_for_tests()
    config = dataclasses.replace(config, database=dataclasses.replace(config.database, url=database))
    background = Background()
    setup = ShotSetup(config, Path("shots"), background=background)
    qtbot.addWidget(setup)
    setup.set_sensitivity(0.312, "µV/(m/s²)")
    with qtbot.waitSignal(setup.advice, timeout=20_000) as said:
        setup.accelerometer_serial.setText("SN-42")
        setup.accelerometer_serial.editingFinished.emit()
    level, text = said.args
    assert level == "warning" and text == ("SN-42: the set-up's nominal 0.312 µV/(m/s²) differs from the lab's record, "
                                           "0.2 µV/(m/s²): check the data sheet before ARM.")
    assert setup.tolerance.value() == 1.0  # from the record
    with qtbot.waitSignal(setup.advice, timeout=20_000) as said:
        setup.sensitivity.setValue(0.2)
    assert said.args[0] == "ok" and "as in the lab's record" in said.args[1]
    background.shutdown()
