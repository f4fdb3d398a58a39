"""Shot set-up: accelerometer, operator, pressure, projectile, analysis options and where the
shot file goes; remembered between runs (QSettings, group "shot"). A target peak (and the
sensor's f_n) gives each projectile's pressure and pulse from the bar model (ui.shot_planner);
"Use" sets the projectile and pressure from it.

`ShotSetup.request(confirm_timeout_s)` turns the form into a rig.shot.ShotRequest; the
sequencer checks it again (`ShotRequest.check`) before anything moves.

With a conditioner set by hand (`[amplifier] driver = "manual"`, drivers/manual_conditioner.py)
the form also asks for what its front panel shows: gain, excitation, low-pass, the sensitivity
set on it and its identity (first from rig.toml, then remembered). `conditioner_entry()` gives
them as `ManualConditioner.enter` takes them; the rig link enters them before the shot (or
campaign) starts, so they are the settings the shot file records.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from hopkinson.rig.config import RigConfig
from hopkinson.rig.shot import PROJECTILES, ShotRequest, second_accelerometer
from hopkinson.ui.shot_planner import ShotPlanner
from hopkinson.ui.widgets import section_title
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSpacerItem,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

MICRO = 1e-6
KILO = 1e3
DEFAULT_MAX_ORDER = 12


class ShotSetup(QWidget):
    """The set-up form (module docstring)."""

    def __init__(self, config: RigConfig, out_dir: Path, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        limits, analysis = config.limits, config.analysis
        self.operator = QLineEdit()
        self.operator.setPlaceholderText("name or initials")
        self.accelerometer_model = QLineEdit()
        self.accelerometer_model.setPlaceholderText("e.g. AYZ-3")
        self.accelerometer_serial = QLineEdit()
        self.accelerometer_serial.setPlaceholderText("serial number")
        # A second accelerometer: only where the rig records a response_2 channel.
        self.accelerometer_2_model: QLineEdit | None = None
        self.accelerometer_2_serial: QLineEdit | None = None
        if "response_2" in config.digitizer.channels:
            self.accelerometer_2_model = QLineEdit()
            self.accelerometer_2_model.setPlaceholderText("on the response_2 channel (optional)")
            self.accelerometer_2_serial = QLineEdit()
            self.accelerometer_2_serial.setPlaceholderText("serial number")
        self.sensitivity = QDoubleSpinBox()
        self.sensitivity.setDecimals(4)
        self.sensitivity.setRange(1e-4, 1e6)
        self.sensitivity.setSuffix(" µV/(m/s²)")
        self.sensitivity.setValue(analysis.sensitivity_v_per_m_s2 / MICRO)
        self.pressure = QDoubleSpinBox()
        self.pressure.setDecimals(2)
        self.pressure.setRange(limits.min_pressure_bar, limits.max_pressure_bar)
        self.pressure.setSingleStep(0.1)
        self.pressure.setSuffix(" bar")
        self.pressure.setValue(min(max(2.0, limits.min_pressure_bar), limits.max_pressure_bar))
        self.projectile = QComboBox()
        for n in PROJECTILES:
            self.projectile.addItem(f"No. {n}", n)
        self.projectile.setCurrentIndex(2)
        self.planner = ShotPlanner(config, self.use_plan, PROJECTILES)
        self.max_order = QSpinBox()
        self.max_order.setRange(1, 40)
        self.max_order.setValue(DEFAULT_MAX_ORDER)
        self.sample_rate = QDoubleSpinBox()
        self.sample_rate.setDecimals(0)
        self.sample_rate.setRange(10, 10_000)
        self.sample_rate.setSuffix(" kS/s")
        self.sample_rate.setValue(analysis.sample_rate_hz / 1e3)
        self.dcm_ratio = QDoubleSpinBox()
        self.dcm_ratio.setDecimals(2)
        self.dcm_ratio.setRange(0.0, 100.0)
        self.dcm_ratio.setSingleStep(0.5)
        self.dcm_ratio.setSpecialValueText("auto")  # 0 = chosen by the analysis
        self.dcm_ratio.setValue(0.0)
        self.dcm_damping = QDoubleSpinBox()
        self.dcm_damping.setDecimals(3)
        self.dcm_damping.setRange(0.01, 1.0)
        self.dcm_damping.setSingleStep(0.05)
        self.dcm_damping.setValue(0.707)
        self.out_dir = QLineEdit(str(out_dir))
        out_row = _with_browse(self.out_dir, "choose the folder for shot files", self._browse)

        # The sensor's sine calibration (optional): each shot's model is fitted to it too (analysis.sine_joint).
        self.sine_calibration = QLineEdit()
        self.sine_calibration.setPlaceholderText("optional: the sensor's sine calibration CSV")
        self.sine_calibration.setToolTip("fit one model to each shot and this sine calibration of the same sensor "
                                         "(frequency_hz,magnitude,phase_deg[,u_magnitude_rel,u_phase_deg]); "
                                         "their consistency is reported")
        sine_row = _with_browse(self.sine_calibration, "choose the sine calibration file", self._browse_sine)

        self.conditioner = _ConditionerFields(config) if config.amplifier.driver == "manual" else None

        for spin in (self.sensitivity, self.pressure, self.sample_rate, self.dcm_ratio, self.dcm_damping,
                     self.max_order):
            spin.setKeyboardTracking(False)

        layout = QVBoxLayout(self)
        layout.setContentsMargins(8, 4, 8, 4)
        layout.setSpacing(2)
        layout.addWidget(section_title("Shot set-up"))
        form = QFormLayout()
        form.setVerticalSpacing(3)
        form.addRow("Operator", self.operator)
        form.addRow("Accelerometer", self.accelerometer_model)
        form.addRow("Serial No.", self.accelerometer_serial)
        form.addRow("Sensitivity", self.sensitivity)
        form.addRow("Sine calibration", sine_row)
        if self.accelerometer_2_model is not None and self.accelerometer_2_serial is not None:
            form.addRow("2nd accelerometer", self.accelerometer_2_model)
            form.addRow("its serial No.", self.accelerometer_2_serial)
        form.addRow("Target peak", self.planner.target_g)
        form.addRow("Sensor f_n", self.planner.sensor_fn_khz)
        form.addRow(self.planner)
        form.addRow("Pressure", self.pressure)
        form.addRow("Projectile", self.projectile)
        form.addRow("Max. order", self.max_order)
        form.addRow("Analysis rate", self.sample_rate)
        form.addRow("DCM ratio r", self.dcm_ratio)
        form.addRow("DCM damping ζₑ", self.dcm_damping)
        form.addRow("Shot folder", out_row)
        if self.conditioner is not None:  # in the same form: its fields line up with the others
            form.addItem(QSpacerItem(0, 4))
            form.addRow(section_title("Conditioner (set by hand)"))
            self.conditioner.add_rows(form)
        layout.addLayout(form)

    # -- the request ---------------------------------------------------------------------------
    def request(self, confirm_timeout_s: float) -> ShotRequest:
        """The form as a ShotRequest (ShotRequest.check validates it)."""
        ratio = self.dcm_ratio.value()
        return ShotRequest(
            pressure_bar=round(self.pressure.value(), 6),
            projectile=int(self.projectile.currentData()),
            operator=self.operator.text().strip(),
            accelerometer_model=self.accelerometer_model.text().strip(),
            accelerometer_serial=self.accelerometer_serial.text().strip(),
            sensor_identities=self._second_accelerometer(),
            sensitivity_v_per_m_s2=self.sensitivity.value() * MICRO,
            max_order=self.max_order.value(),
            sample_rate_hz=self.sample_rate.value() * 1e3,
            dcm_ratio=ratio if ratio > 0 else None,
            dcm_damping=self.dcm_damping.value(),
            sine_calibration=self.sine_calibration.text().strip() or None,
            out_dir=Path(self.out_dir.text().strip() or "."),
            confirm_timeout_s=confirm_timeout_s,
        )

    def use_plan(self, projectile: int, pressure_bar: float) -> None:
        """Set the projectile and pressure the planner chose (within the rig's limits)."""
        index = self.projectile.findData(projectile)
        if index >= 0:
            self.projectile.setCurrentIndex(index)
        self.pressure.setValue(pressure_bar)

    def _second_accelerometer(self) -> dict[str, dict[str, str]]:
        """The second accelerometer's model and serial (ShotRequest.check asks for both)."""
        if self.accelerometer_2_model is None or self.accelerometer_2_serial is None:
            return {}
        return second_accelerometer(self.accelerometer_2_model.text(), self.accelerometer_2_serial.text())

    def conditioner_entry(self) -> dict[str, Any] | None:
        """The hand-set conditioner's values as ManualConditioner.enter takes them (None: the
        amplifier is not set by hand)."""
        return self.conditioner.entry() if self.conditioner is not None else None

    def set_enabled_for_shot(self, idle: bool) -> None:
        """The form is read-only while a shot runs."""
        for child in self.findChildren(QWidget):
            if child is not self:
                child.setEnabled(idle)

    # -- remembered between runs ------------------------------------------------------------------
    def save(self, settings: QSettings) -> None:
        settings.beginGroup("shot")
        try:
            for key, edit in self._texts().items():
                settings.setValue(key, edit.text())
            for key, spin in self._numbers().items():
                settings.setValue(key, float(spin.value()))
            settings.setValue("projectile", int(self.projectile.currentData()))
        finally:
            settings.endGroup()
        settings.sync()

    def load(self, settings: QSettings) -> None:
        settings.beginGroup("shot")
        try:
            for key, edit in self._texts().items():
                value = settings.value(key)
                if value is not None:
                    edit.setText(str(value))
            for key, spin in self._numbers().items():
                value = settings.value(key)
                try:
                    if value is not None:
                        spin.setValue(type(spin.value())(float(value)))
                except (TypeError, ValueError):
                    pass  # a damaged setting keeps the default
            projectile = settings.value("projectile")
            index = self.projectile.findData(int(projectile)) if str(projectile or "").isdigit() else -1
            if index >= 0:
                self.projectile.setCurrentIndex(index)
        finally:
            settings.endGroup()

    def _texts(self) -> dict[str, QLineEdit]:
        texts = {"operator": self.operator, "accelerometer_model": self.accelerometer_model,
                 "accelerometer_serial": self.accelerometer_serial, "out_dir": self.out_dir,
                 "sine_calibration": self.sine_calibration}
        if self.accelerometer_2_model is not None and self.accelerometer_2_serial is not None:
            texts |= {"accelerometer_2_model": self.accelerometer_2_model,
                      "accelerometer_2_serial": self.accelerometer_2_serial}
        return texts | ({"conditioner_identity": self.conditioner.identity} if self.conditioner else {})

    def _numbers(self) -> dict[str, QDoubleSpinBox | QSpinBox]:
        numbers: dict[str, QDoubleSpinBox | QSpinBox] = {
            "sensitivity_uv_per_m_s2": self.sensitivity, "pressure_bar": self.pressure,
            "max_order": self.max_order, "sample_rate_khz": self.sample_rate,
            "dcm_ratio": self.dcm_ratio, "dcm_damping": self.dcm_damping,
            "target_peak_g": self.planner.target_g, "sensor_fn_khz": self.planner.sensor_fn_khz}
        return numbers | (self.conditioner.numbers() if self.conditioner else {})

    def _browse(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Folder for shot files", self.out_dir.text())
        if folder:
            self.out_dir.setText(folder)

    def _browse_sine(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Sine calibration of the sensor", self.sine_calibration.text(),
                                              "CSV (*.csv);;all files (*)")
        if path:
            self.sine_calibration.setText(path)


class _ConditionerFields:
    """The entry fields of a conditioner set by hand (module docstring), first from rig.toml."""

    def __init__(self, config: RigConfig) -> None:
        amp = config.amplifier
        self.gain = _spin(3, (0.001, 1e6), amp.gain, "", "gain: output volts per input volt")
        self.excitation = _spin(2, (0.0, 20.0), amp.excitation_v, " V", "bridge excitation; none for IEPE or charge",
                                special="none")
        self.lowpass = _spin(1, (0.0, 1e5), amp.lowpass_hz / KILO, " kHz", "the filter corner", special="off")
        self.sensitivity = _spin(4, (0.0, 1e6), amp.sensitivity_v_per_m_s2 / MICRO, " µV/(m/s²)",
                                 "the sensor sensitivity set on the conditioner, if it has one",
                                 special="not entered")
        self.identity = QLineEdit(amp.identity)
        self.identity.setPlaceholderText("make, model, serial")

    def add_rows(self, form: QFormLayout) -> None:
        note = QLabel("as set on its front panel; recorded in the shot file")
        note.setStyleSheet("color: #5f6368;")
        form.addRow(note)
        for label, field in (("Gain", self.gain), ("Excitation", self.excitation), ("Low-pass", self.lowpass),
                             ("Sensitivity", self.sensitivity), ("Identity", self.identity)):
            form.addRow(label, field)

    def numbers(self) -> dict[str, QDoubleSpinBox]:
        return {"conditioner_gain": self.gain, "conditioner_excitation_v": self.excitation,
                "conditioner_lowpass_khz": self.lowpass, "conditioner_sensitivity_uv_per_m_s2": self.sensitivity}

    def entry(self) -> dict[str, Any]:
        sensitivity = self.sensitivity.value() * MICRO
        return {"gain": self.gain.value(), "excitation_v": self.excitation.value(),
                "lowpass_hz": self.lowpass.value() * KILO, "sensitivity_v_per_m_s2": sensitivity or None,
                "identity": self.identity.text().strip()}


def _with_browse(edit: QLineEdit, tip: str, browse: Callable[[], None]) -> QHBoxLayout:
    """A path field with its "…" button (which calls `browse`) beside it."""
    button = QPushButton("…")
    button.setFixedWidth(28)
    button.setToolTip(tip)
    button.clicked.connect(browse)
    row = QHBoxLayout()
    row.setContentsMargins(0, 0, 0, 0)
    row.addWidget(edit, 1)
    row.addWidget(button)
    return row


def _spin(decimals: int, limits: tuple[float, float], value: float, suffix: str, tip: str,
          special: str = "") -> QDoubleSpinBox:
    """A number field (its lowest value shown as `special`, when given)."""
    spin = QDoubleSpinBox()
    spin.setDecimals(decimals)
    spin.setRange(*limits)
    spin.setSuffix(suffix)
    spin.setToolTip(tip)
    if special:
        spin.setSpecialValueText(special)
    spin.setValue(value)
    spin.setKeyboardTracking(False)
    return spin
