"""The campaign plan editor: a plan's name, operator, sensor (nominal sensitivity in its own
unit, tolerance, the transverse sensitivity and asymmetry bound it states), authorisation and
its shot entries (a pressure in bar or a target peak in g, the projectile, the repeats),
written as the plan TOML `hopkinson campaign run` reads (rig.plan; checked by
rig.plan.plan_from_dict before it is saved).

Editing a loaded plan keeps what the editor does not show (its [defaults], each entry's
[shots.analysis] overrides, a sine calibration, a second accelerometer): the editor changes only
the keys it has fields for. `plan_document` is the pure part (tested on its own); `PlanEditor`
is the dialog.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QDialog,
    QDialogButtonBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QPushButton,
    QTableWidget,
    QVBoxLayout,
    QWidget,
)

from hopkinson.analysis.sensitivity_units import DEFAULT_UNIT, G_M_S2, UNITS
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan import CampaignPlan, plan_from_dict
from hopkinson.rig.shot import PROJECTILES, SENSOR_STATED
from hopkinson.ui.inputs import ComboBox, IntSpinBox, UnitSpinBox
from hopkinson.ui.sensor_stated import StatedFields
from hopkinson.ui.widgets import TEXT_COLOURS

PRESSURE, TARGET = "pressure (bar)", "target (g)"


@dataclass(frozen=True)
class PlanEntry:
    """One [[shots]] entry: a level (bar or g), the projectile and the repeats; `extra`: the
    entry's other keys, kept as they were (its analysis overrides)."""

    kind: str  # PRESSURE or TARGET
    value: float
    projectile: int
    repeats: int
    extra: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class PlanFields:
    name: str
    operator: str
    model: str
    serial: str
    sensitivity: float  # nominal, in `unit` (0: not given)
    unit: str
    tolerance_percent: float  # 0: not given
    authorise_firing: bool
    description: str = ""
    # what the sensor's data sheet states (rig.shot.SENSOR_STATED), fractions (absent or None: not
    # stated: the rig config's [uncertainty] value)
    stated: Mapping[str, float | None] = field(default_factory=dict)


def plan_document(fields: PlanFields, entries: list[PlanEntry], base: dict[str, Any] | None = None) -> dict[str, Any]:
    """The plan as a TOML table: `base` (a loaded plan's table) with the editor's keys set."""
    doc = copy.deepcopy(base) if base else {}
    doc["name"], doc["operator"] = fields.name.strip(), fields.operator.strip()
    if fields.description.strip():
        doc["description"] = fields.description.strip()
    doc["authorise_firing"] = bool(fields.authorise_firing)
    acc = dict(doc.get("accelerometer") or {})
    acc["model"], acc["serial"] = fields.model.strip(), fields.serial.strip()
    for key in ("sensitivity_v_per_m_s2", "sensitivity_unit", "tolerance_percent", *SENSOR_STATED):
        acc.pop(key, None)
    if fields.sensitivity > 0:
        unit = UNITS[fields.unit]
        acc["sensitivity_v_per_m_s2"] = unit.to_si(fields.sensitivity)
        acc["sensitivity_unit"] = unit.name
    if fields.tolerance_percent > 0:
        acc["tolerance_percent"] = fields.tolerance_percent
    acc |= {key: value for key, value in fields.stated.items() if value is not None}
    doc["accelerometer"] = acc
    shots = []
    for e in entries:
        table: dict[str, Any] = {k: v for k, v in e.extra if k not in ("pressure_bar", "peak_g", "peak_m_s2")}
        if e.kind == PRESSURE:
            table["pressure_bar"] = e.value
        else:
            table["peak_g"] = e.value
        table["projectile"], table["repeats"] = e.projectile, e.repeats
        shots.append(table)
    doc["shots"] = shots
    return doc


def entries_of(doc: dict[str, Any]) -> list[PlanEntry]:
    """A plan table's [[shots]] entries as the editor shows them ([defaults] filling the gaps)."""
    defaults = doc.get("defaults") or {}
    out = []
    for table in doc.get("shots") or []:
        merged = {**{k: v for k, v in defaults.items() if k != "analysis"}, **table}
        if "peak_g" in merged:
            kind, value = TARGET, float(merged["peak_g"])
        elif "peak_m_s2" in merged:
            kind, value = TARGET, float(merged["peak_m_s2"]) / G_M_S2
        else:
            kind, value = PRESSURE, float(merged.get("pressure_bar", 2.0))
        extra = tuple((k, v) for k, v in table.items() if k not in ("projectile", "repeats"))
        out.append(PlanEntry(kind, value, int(merged.get("projectile", 3)), int(table.get("repeats", 1)), extra))
    return out


def save_plan(doc: dict[str, Any], path: Path) -> CampaignPlan:
    """Check the plan (rig.plan: ConfigError naming the key) and write it, atomically."""
    import tomli_w

    from hopkinson.fileio import atomic_write

    plan = plan_from_dict(doc, path)
    atomic_write(path, tomli_w.dumps(doc))
    return plan


class PlanEditor(QDialog):
    """The plan editor dialog (module docstring); `saved_path` is set once it wrote the plan."""

    def __init__(self, parent: QWidget | None = None, plan: CampaignPlan | None = None, doc: dict[str, Any] | None = None,
                 folder: Path = Path(".")) -> None:
        super().__init__(parent)
        self.setWindowTitle("Campaign plan")
        self.resize(760, 560)
        self.base = doc or {}
        self.folder = Path(plan.path).parent if plan is not None else folder
        self.path: Path | None = Path(plan.path) if plan is not None else None
        self.saved_path: Path | None = None
        acc = self.base.get("accelerometer") or {}
        self.name = QLineEdit(str(self.base.get("name", "")))
        self.name.setPlaceholderText("e.g. ayz3-sn0001 (the run folders are named after it)")
        self.operator = QLineEdit(str(self.base.get("operator", "")))
        self.model = QLineEdit(str(acc.get("model", "")))
        self.serial = QLineEdit(str(acc.get("serial", "")))
        unit_name = str(acc.get("sensitivity_unit") or DEFAULT_UNIT)
        unit = UNITS.get(unit_name, UNITS[DEFAULT_UNIT])
        self.unit = ComboBox()
        for name in UNITS:
            self.unit.addItem(name, name)
        self.unit.setCurrentIndex(self.unit.findData(unit.name))
        nominal = acc.get("sensitivity_v_per_m_s2")
        self.sensitivity = UnitSpinBox("Nominal sensitivity", "", unit.plausible_range(),
                                       unit.from_si(float(nominal)) if nominal else 0.0, decimals=4, special="not given")
        self.unit.currentIndexChanged.connect(
            lambda: self.sensitivity.set_plausible(*UNITS[str(self.unit.currentData())].plausible_range()))
        self.tolerance = UnitSpinBox("Tolerance", "%", (0.1, 50.0), float(acc.get("tolerance_percent") or 0.0),
                                     decimals=1, special="not set")
        self.stated = StatedFields(acc, unset_text="the rig's")
        self.authorise = QCheckBox("fire every shot without asking (else each shot is confirmed with FIRE)")
        self.authorise.setChecked(bool(self.base.get("authorise_firing", False)))
        self.message = QLabel("")
        self.message.setWordWrap(True)
        for spin in (self.sensitivity, self.tolerance, *self.stated.spins.values()):
            spin.refused.connect(lambda text: self._say("warning", f"Not taken: {text}."))

        self.table = QTableWidget(0, 4)
        self.table.setHorizontalHeaderLabels(["level", "value", "projectile", "repeats"])
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.table.verticalHeader().setVisible(False)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self._extras: list[tuple[tuple[str, Any], ...]] = []
        for entry in entries_of(self.base) or [PlanEntry(TARGET, 50_000.0, 3, 3)]:
            self.add_entry(entry)
        add = QPushButton("Add level")
        remove = QPushButton("Remove selected")
        add.clicked.connect(lambda: self.add_entry(self.entries()[-1] if self.table.rowCount() else
                                                   PlanEntry(TARGET, 50_000.0, 3, 3)))
        remove.clicked.connect(self._remove_selected)

        form = QFormLayout()
        form.addRow("Plan name", self.name)
        form.addRow("Operator", self.operator)
        form.addRow("Accelerometer", self.model)
        form.addRow("Serial No.", self.serial)
        row = QHBoxLayout()
        row.addWidget(self.sensitivity, 1)
        row.addWidget(self.unit)
        form.addRow("Nominal sens.", row)
        form.addRow("Tolerance (± %)", self.tolerance)
        self.stated.add_rows(form)
        form.addRow("", self.authorise)
        buttons_row = QHBoxLayout()
        buttons_row.addWidget(add)
        buttons_row.addWidget(remove)
        buttons_row.addStretch(1)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Save | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.save)
        buttons.rejected.connect(self.reject)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(QLabel("Levels (shots are fired in this order; a target level's pressure is chosen by "
                                "the level control):"))
        layout.addWidget(self.table, 1)
        layout.addLayout(buttons_row)
        layout.addWidget(self.message)
        layout.addWidget(buttons)

    # -- entries -------------------------------------------------------------------------------
    def add_entry(self, entry: PlanEntry) -> None:
        row = self.table.rowCount()
        self.table.insertRow(row)
        kind = ComboBox()
        kind.addItems([TARGET, PRESSURE])
        kind.setCurrentText(entry.kind)
        value = UnitSpinBox("Level", "", (0.01, 2e6), entry.value, decimals=2, step=1000.0 if entry.kind == TARGET
                            else 0.1)
        value.refused.connect(lambda text: self._say("warning", f"Not taken: {text}."))
        projectile = ComboBox()
        for n in PROJECTILES:
            projectile.addItem(f"No. {n}", n)
        projectile.setCurrentIndex(max(0, projectile.findData(entry.projectile)))
        repeats = IntSpinBox(1, 1000, entry.repeats)
        for col, widget in enumerate((kind, value, projectile, repeats)):
            self.table.setCellWidget(row, col, widget)
        self._extras.append(entry.extra)

    def entries(self) -> list[PlanEntry]:
        out = []
        for row in range(self.table.rowCount()):
            kind, value, projectile, repeats = (self.table.cellWidget(row, c) for c in range(4))
            out.append(PlanEntry(kind.currentText(), value.value(), int(projectile.currentData()), repeats.value(),
                                 self._extras[row]))
        return out

    def _remove_selected(self) -> None:
        for row in sorted({i.row() for i in self.table.selectedIndexes()}, reverse=True):
            self.table.removeRow(row)
            del self._extras[row]

    # -- saving --------------------------------------------------------------------------------
    def fields(self) -> PlanFields:
        return PlanFields(self.name.text(), self.operator.text(), self.model.text(), self.serial.text(),
                          self.sensitivity.value(), str(self.unit.currentData()), self.tolerance.value(),
                          self.authorise.isChecked(), str(self.base.get("description", "")),
                          self.stated.fractions())

    def ask_path(self) -> Path | None:
        """Where to save the plan (a dialog; tests replace it)."""
        default = self.path or self.folder / f"{self.name.text().strip() or 'plan'}.toml"
        name, _ = QFileDialog.getSaveFileName(self, "Save the campaign plan", str(default), "Plans (*.toml)")
        return Path(name) if name else None

    def save(self) -> None:
        """Check the plan, ask where, write it; the dialog closes once it is written."""
        doc = plan_document(self.fields(), self.entries(), self.base)
        try:
            plan_from_dict(doc, self.path or Path("plan.toml"))
        except ConfigError as exc:
            self._say("error", f"Not saved: {str(exc).split(': ', 1)[-1]}")
            return
        path = self.ask_path()
        if path is None:
            return
        try:
            save_plan(doc, path)
        except (ConfigError, OSError) as exc:
            self._say("error", f"Not saved: {exc}")
            return
        self.saved_path = path
        self.accept()

    def _say(self, level: str, text: str) -> None:
        self.message.setStyleSheet(f"color: {TEXT_COLOURS[level]};")
        self.message.setText(text)
        self.message.setAlignment(Qt.AlignmentFlag.AlignLeft)
