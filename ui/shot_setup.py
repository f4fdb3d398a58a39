"""Shot set-up: accelerometer, operator, pressure, projectile, analysis options and where the
shot file goes; remembered between runs (QSettings, group "shot"). A target peak (and the
sensor's f_n) gives each projectile's pressure and pulse from the bar model (ui.shot_planner);
"Use" sets the projectile and pressure from it.

Units. Every number field states its unit (ui.inputs.UnitSpinBox) and refuses a value outside
its plausible range naming that unit (`refused`: one line for the window's banner). The nominal
sensitivity is entered in the sensor's own unit, chosen beside it (analysis.sensitivity_units:
µV/(m/s²), mV/g, pC/(m/s²), …); the request carries its SI value and the unit's name, which
the shot file records, so results come back in that unit. f_n is in kHz everywhere on the panel.
What the sensor's data sheet states that the budget carries, its transverse sensitivity and a
bound on its tension/compression asymmetry, is entered in per cent (the rig config's
[uncertainty] values until changed); the shot file records both (rig.shot.SENSOR_STATED).

The shot matches the plan. Under the pressure the form shows what the set-up will do
(ui.setup_check: the bar model's peak in g and km/s², the pulse width and the band for the
projectile and pressure actually set) and how far that is from the target; `prediction()` gives
it to the window, which asks before ARM when the target would be missed by more than the level
tolerance or the sensor's range exceeded, and states it in the FIRE confirmation.

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

from PySide6.QtCore import QSettings, QTimer, Signal
from PySide6.QtWidgets import (
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSpacerItem,
    QVBoxLayout,
    QWidget,
)

from hopkinson.analysis.options import AnalysisOverrides, declared
from hopkinson.analysis.sensitivity_units import DEFAULT_UNIT, G_M_S2, UNITS, SensitivityUnit
from hopkinson.rig.config import RigConfig
from hopkinson.rig.shot import PROJECTILES, ShotRequest, second_accelerometer
from hopkinson.ui.inputs import ComboBox, IntSpinBox, UnitSpinBox
from hopkinson.ui.sensor_lookup import RecordAdvice, record_advice
from hopkinson.ui.sensor_stated import StatedFields
from hopkinson.ui.setup_check import SetupPrediction, predict_setup
from hopkinson.ui.shot_planner import ShotPlanner
from hopkinson.ui.widgets import TEXT_COLOURS, section_title
from hopkinson.ui.worker import Background

KILO = 1e3
DEFAULT_MAX_ORDER = declared("max_order")  # analysis.options, as every default of an analysis option
PREDICTION_DELAY_MS = 150  # the prediction follows the fields after this pause (one takes ~0.1 s)


class ShotSetup(QWidget):
    """The set-up form (module docstring)."""

    refused = Signal(str)  # a value refused by a field: one line naming the unit
    changed = Signal()  # the prediction was drawn again (tests wait on it)
    advice = Signal(str, str)  # level, what the lab's record says of the sensor (ui.sensor_lookup)

    def __init__(self, config: RigConfig, out_dir: Path, parent: QWidget | None = None,
                 background: Background | None = None) -> None:
        super().__init__(parent)
        self._background = background
        self._database_url = config.database.url
        limits, analysis = config.limits, config.analysis
        self._rig = config.bar.rig()
        self._prediction: SetupPrediction | None = None
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
        self.sensitivity_unit = ComboBox()
        for name in UNITS:
            self.sensitivity_unit.addItem(name, name)
        self.sensitivity_unit.setCurrentIndex(self.sensitivity_unit.findData(DEFAULT_UNIT))
        self.sensitivity_unit.setToolTip("the unit of the sensor's data sheet; results are shown in it")
        default = UNITS[DEFAULT_UNIT]
        self.sensitivity = UnitSpinBox("Nominal sensitivity", "", default.plausible_range(),
                                       default.from_si(analysis.sensitivity_v_per_m_s2), decimals=4, step=0.01,
                                       tip="the sensor's nominal sensitivity at the conditioner input, in the unit "
                                           "beside it")
        self.tolerance = UnitSpinBox("Tolerance", "%", (0.1, 50.0), 0.0, decimals=1, step=0.5, special="not set",
                                     tip="the sensor's tolerance on its nominal sensitivity: a shot outside it is "
                                         "flagged")
        # what the sensor states, starting at the rig's values (those of a sensor that states none)
        self.stated = StatedFields(config.uncertainty.analysis_options())
        self.sensor_range = UnitSpinBox("Sensor range", "g", (100.0, 2e6), 0.0, decimals=0, step=1000.0,
                                        special="not set", tip="the highest shock the sensor is rated for: a set-up "
                                                               "predicted above it asks before ARM")
        self.pressure = UnitSpinBox("Pressure", "bar", (limits.min_pressure_bar, limits.max_pressure_bar),
                                    min(max(2.0, limits.min_pressure_bar), limits.max_pressure_bar), step=0.1,
                                    tip="reservoir pressure (gauge), within the rig's limits")
        self.projectile = ComboBox()
        for n in PROJECTILES:
            self.projectile.addItem(f"No. {n}", n)
        self.projectile.setCurrentIndex(2)
        self.planner = ShotPlanner(config, self.use_plan, PROJECTILES)
        self.prediction_label = QLabel("")
        self.prediction_label.setWordWrap(True)
        self.max_order = IntSpinBox(1, 40, DEFAULT_MAX_ORDER)
        self.sample_rate = UnitSpinBox("Analysis rate", "kS/s", (10.0, 10_000.0), analysis.sample_rate_hz / KILO,
                                       decimals=0, step=100.0)
        self.dcm_ratio = UnitSpinBox("DCM ratio r", "", (0.1, 200.0), 0.0, step=0.5, special="auto",
                                     tip="0 = auto: the ratio that widens the ±5 % band as the rig asks")
        self.dcm_damping = UnitSpinBox("DCM damping ζₑ", "", (0.01, 1.0), declared("dcm_damping"), decimals=3,
                                       step=0.05)
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

        sensitivity_row = QHBoxLayout()
        sensitivity_row.setContentsMargins(0, 0, 0, 0)
        sensitivity_row.addWidget(self.sensitivity, 1)
        sensitivity_row.addWidget(self.sensitivity_unit)

        layout = QVBoxLayout(self)
        layout.setContentsMargins(8, 4, 8, 4)
        layout.setSpacing(2)
        layout.addWidget(section_title("Shot set-up"))
        form = QFormLayout()
        form.setVerticalSpacing(3)
        form.addRow("Operator", self.operator)
        form.addRow("Accelerometer", self.accelerometer_model)
        form.addRow("Serial No.", self.accelerometer_serial)
        form.addRow("Nominal sens.", sensitivity_row)
        form.addRow("Tolerance (± %)", self.tolerance)
        form.addRow("Sensor range (g)", self.sensor_range)
        self.stated.add_rows(form)
        form.addRow("Sine calibration", sine_row)
        if self.accelerometer_2_model is not None and self.accelerometer_2_serial is not None:
            form.addRow("2nd accelerometer", self.accelerometer_2_model)
            form.addRow("its serial No.", self.accelerometer_2_serial)
        form.addRow("Target peak (g)", self.planner.target_g)
        form.addRow("Sensor f_n (kHz)", self.planner.sensor_fn_khz)
        form.addRow(self.planner)
        form.addRow("Pressure (bar)", self.pressure)
        form.addRow("Projectile", self.projectile)
        form.addRow(self.prediction_label)
        form.addRow("Max. order", self.max_order)
        form.addRow("Analysis (kS/s)", self.sample_rate)
        form.addRow("DCM ratio r", self.dcm_ratio)
        form.addRow("DCM damping ζₑ", self.dcm_damping)
        form.addRow("Shot folder", out_row)
        if self.conditioner is not None:  # in the same form: its fields line up with the others
            form.addItem(QSpacerItem(0, 4))
            form.addRow(section_title("Conditioner (set by hand)"))
            self.conditioner.add_rows(form)
        layout.addLayout(form)

        for spin in self.findChildren(UnitSpinBox):
            spin.refused.connect(self.refused)
        self._predict_timer = QTimer(self)
        self._predict_timer.setSingleShot(True)
        self._predict_timer.setInterval(PREDICTION_DELAY_MS)
        self._predict_timer.timeout.connect(self.update_prediction)
        for spin in (self.pressure, self.sensor_range, self.planner.target_g):
            spin.value_accepted.connect(self._predict_timer.start)
        self.projectile.currentIndexChanged.connect(self._predict_timer.start)
        self.sensitivity_unit.currentIndexChanged.connect(self._unit_changed)
        self.accelerometer_serial.editingFinished.connect(self.check_record)
        self.sensitivity.value_accepted.connect(self.check_record)
        self.update_prediction()

    # -- units ----------------------------------------------------------------------------------
    @property
    def unit(self) -> SensitivityUnit:
        return UNITS[str(self.sensitivity_unit.currentData())]

    def _unit_changed(self) -> None:
        """The number stays what was typed; it now means the new unit (and must be plausible in it)."""
        self.sensitivity.set_plausible(*self.unit.plausible_range())

    def set_sensitivity(self, value: float, unit_name: str) -> None:
        """Put a nominal sensitivity in its unit into the form."""
        index = self.sensitivity_unit.findData(unit_name)
        if index >= 0:
            self.sensitivity_unit.setCurrentIndex(index)
        self.sensitivity.setValue(value)

    def check_record(self) -> None:
        """The sensor against the lab's record, off the GUI thread: a nominal that differs is said
        (`advice`), a tolerance the form lacks is taken from it (ui.sensor_lookup)."""
        serial = self.accelerometer_serial.text().strip()
        if not serial or self._background is None or not self.isEnabled():
            return
        nominal, tolerance = self.unit.to_si(self.sensitivity.value()), self.tolerance.value() or None
        url = self._database_url
        self._background.run(lambda: record_advice(url, serial, nominal, tolerance), self._take_advice,
                             lambda exc: self.advice.emit("warning", f"The lab's record was not read: {exc}"))

    def _take_advice(self, advice: RecordAdvice) -> None:
        if advice.tolerance_percent and not self.tolerance.value():
            self.tolerance.setValue(advice.tolerance_percent)
        if advice.level:
            self.advice.emit(advice.level, advice.text)

    # -- the prediction ------------------------------------------------------------------------
    def prediction(self) -> SetupPrediction | None:
        """The bar model's shot for the set-up now (None when the model cannot predict it)."""
        target = self.planner.target_g.value() * G_M_S2
        range_m_s2 = self.sensor_range.value() * G_M_S2
        try:
            return predict_setup(self._rig, int(self.projectile.currentData()), self.pressure.value(),
                                 target or None, range_m_s2 or None)
        except ValueError:
            return None

    def update_prediction(self) -> None:
        """Show what the set-up will do, and how far that is from the target (module docstring)."""
        self._predict_timer.stop()
        p = self._prediction = self.prediction()
        if p is None:
            self.prediction_label.setText("<span style='color:#5f6368'>the bar model cannot predict this set-up</span>")
        else:
            problems = p.problems()
            colour = TEXT_COLOURS["warning"] if problems else TEXT_COLOURS["ok"] if p.target_m_s2 else "#3c4043"
            verdict = (" — " + "; ".join(problems) if problems else
                       f" — {p.target_text()}, within ±{100 * p.level_tolerance_rel:g} %" if p.target_m_s2 else "")
            self.prediction_label.setText(f"<span style='color:{colour}'><b>This set-up:</b> {p.summary()}"
                                          f"{verdict}</span>")
        self.changed.emit()

    # -- the request ---------------------------------------------------------------------------
    def request(self, confirm_timeout_s: float) -> ShotRequest:
        """The form as a ShotRequest (ShotRequest.check validates it)."""
        ratio = self.dcm_ratio.value()
        tolerance = self.tolerance.value()
        prediction = self.prediction()
        return ShotRequest(
            pressure_bar=round(self.pressure.value(), 6),
            projectile=int(self.projectile.currentData()),
            operator=self.operator.text().strip(),
            accelerometer_model=self.accelerometer_model.text().strip(),
            accelerometer_serial=self.accelerometer_serial.text().strip(),
            sensor_identities=self._second_accelerometer(),
            sensitivity_unit=self.unit.name,
            tolerance_percent=tolerance or None,
            analysis=AnalysisOverrides(
                sensitivity_v_per_m_s2=self.unit.to_si(self.sensitivity.value()),
                **self.stated.fractions(),
                max_order=self.max_order.value(),
                sample_rate_hz=self.sample_rate.value() * 1e3,
                dcm_ratio=ratio if ratio > 0 else None,
                dcm_damping=self.dcm_damping.value(),
                sine_calibration=self.sine_calibration.text().strip() or None),
            out_dir=Path(self.out_dir.text().strip() or "."),
            confirm_timeout_s=confirm_timeout_s,
            level=_level(prediction),
        )

    def use_plan(self, projectile: int, pressure_bar: float) -> None:
        """Set the projectile and pressure the planner chose (within the rig's limits)."""
        index = self.projectile.findData(projectile)
        if index >= 0:
            self.projectile.setCurrentIndex(index)
        self.pressure.setValue(pressure_bar)
        self.update_prediction()

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
            settings.setValue("sensitivity_unit", self.unit.name)
        finally:
            settings.endGroup()
        settings.sync()

    def load(self, settings: QSettings) -> None:
        settings.beginGroup("shot")
        try:
            unit = settings.value("sensitivity_unit")
            index = self.sensitivity_unit.findData(str(unit)) if unit is not None else -1
            if index >= 0:
                self.sensitivity_unit.setCurrentIndex(index)
            for key, edit in self._texts().items():
                value = settings.value(key)
                if value is not None:
                    edit.setText(str(value))
            for key, spin in self._numbers().items():
                value = settings.value(key)
                try:
                    if value is not None:
                        spin.setValue(type(spin.value())(float(value)))  # an implausible one is refused
                except (TypeError, ValueError):
                    pass  # a damaged setting keeps the default
            projectile = settings.value("projectile")
            index = self.projectile.findData(int(projectile)) if str(projectile or "").isdigit() else -1
            if index >= 0:
                self.projectile.setCurrentIndex(index)
        finally:
            settings.endGroup()
        self.update_prediction()

    def _texts(self) -> dict[str, QLineEdit]:
        texts = {"operator": self.operator, "accelerometer_model": self.accelerometer_model,
                 "accelerometer_serial": self.accelerometer_serial, "out_dir": self.out_dir,
                 "sine_calibration": self.sine_calibration}
        if self.accelerometer_2_model is not None and self.accelerometer_2_serial is not None:
            texts |= {"accelerometer_2_model": self.accelerometer_2_model,
                      "accelerometer_2_serial": self.accelerometer_2_serial}
        return texts | ({"conditioner_identity": self.conditioner.identity} if self.conditioner else {})

    def _numbers(self) -> dict[str, UnitSpinBox | IntSpinBox]:
        numbers: dict[str, UnitSpinBox | IntSpinBox] = {
            # the key keeps its old name: a set-up remembered before units were chosen was in µV/(m/s²)
            "sensitivity_uv_per_m_s2": self.sensitivity, "pressure_bar": self.pressure,
            "tolerance_percent": self.tolerance, "sensor_range_g": self.sensor_range,
            "transverse_sensitivity_percent": self.stated.spins["transverse_sensitivity_rel"],
            "asymmetry_bound_percent": self.stated.spins["asymmetry_bound_rel"],
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


def _level(prediction: SetupPrediction | None) -> dict[str, Any] | None:
    """The target level as the shot file records it (rig.level_control.LevelChoice's keys), with
    the bar model's peak for the pressure set: None without a target."""
    if prediction is None or prediction.target_m_s2 is None:
        return None
    return {"target_peak_m_s2": prediction.target_m_s2, "pressure_bar": prediction.pressure_bar,
            "predicted_peak_m_s2": prediction.peak_m_s2, "correction": 1.0,
            "basis": "the bar model (pressure set on the panel)", "points_used": 0, "held_at_limit": False}


class _ConditionerFields:
    """The entry fields of a conditioner set by hand (module docstring), first from rig.toml."""

    def __init__(self, config: RigConfig) -> None:
        amp = config.amplifier
        unit = UNITS[DEFAULT_UNIT]
        self.gain = UnitSpinBox("Conditioner gain", "", (0.001, 1e6), amp.gain, decimals=3,
                                tip="gain: output volts per input volt")
        self.excitation = UnitSpinBox("Excitation", "V", (0.1, 20.0), amp.excitation_v, special="none",
                                      tip="bridge excitation; none for IEPE or charge")
        self.lowpass = UnitSpinBox("Low-pass", "kHz", (0.1, 1e5), amp.lowpass_hz / KILO, decimals=1, special="off",
                                   tip="the filter corner")
        self.sensitivity = UnitSpinBox("Conditioner sensitivity", unit.name, unit.plausible_range(),
                                       unit.from_si(amp.sensitivity_v_per_m_s2), decimals=4, special="not entered",
                                       tip="the sensor sensitivity set on the conditioner, if it has one")
        self.identity = QLineEdit(amp.identity)
        self.identity.setPlaceholderText("make, model, serial")

    def add_rows(self, form: QFormLayout) -> None:
        note = QLabel("as set on its front panel; recorded in the shot file")
        note.setStyleSheet("color: #5f6368;")
        form.addRow(note)
        for label, field in (("Gain (V/V)", self.gain), ("Excitation (V)", self.excitation),
                             ("Low-pass (kHz)", self.lowpass), ("Sensitivity", self.sensitivity),
                             ("Identity", self.identity)):
            form.addRow(label, field)

    def numbers(self) -> dict[str, UnitSpinBox]:
        return {"conditioner_gain": self.gain, "conditioner_excitation_v": self.excitation,
                "conditioner_lowpass_khz": self.lowpass, "conditioner_sensitivity_uv_per_m_s2": self.sensitivity}

    def entry(self) -> dict[str, Any]:
        sensitivity = UNITS[DEFAULT_UNIT].to_si(self.sensitivity.value())
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
