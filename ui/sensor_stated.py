"""What a sensor's data sheet states that the budget carries (rig.shot.SENSOR_STATED: its
transverse sensitivity and a bound on its tension/compression asymmetry), as two per-cent
fields: one definition for the panel's shot set-up and the plan editor."""

from __future__ import annotations

from collections.abc import Mapping

from PySide6.QtWidgets import QFormLayout

from hopkinson.rig.shot import SENSOR_STATED
from hopkinson.ui.inputs import UnitSpinBox

# SENSOR_STATED's option -> (the field's row label, its name in messages, its tooltip)
_FIELDS = {
    "transverse_sensitivity_rel": (
        "Transverse sens.", "Transverse sensitivity",
        "the sensor's stated (data-sheet) transverse sensitivity: times the bar's transverse motion, a Type B "
        "row of the sensitivity's uncertainty"),
    "asymmetry_bound_rel": (
        "Asymmetry bound", "Asymmetry bound",
        "a bound on the sensor's tension/compression asymmetry: carried (half of it) where a pulse drives one "
        "direction only"),
}
assert tuple(_FIELDS) == SENSOR_STATED


class StatedFields:
    """One UnitSpinBox in per cent per SENSOR_STATED option (`spins`, by option name).

    values_rel: each option's value, a fraction (None or 0: not stated). unset_text: the text
    shown at 0 when a field may be left "not stated" (the plan editor's "the rig's": the plan
    then leaves the option to the rig config); "" when every value is stated (the panel)."""

    def __init__(self, values_rel: Mapping[str, float | None], unset_text: str = "") -> None:
        self.unset_text = unset_text
        low = 0.01 if unset_text else 0.0
        unset_tip = "; not set: the rig config's [uncertainty] value" if unset_text else ""
        self.spins = {name: UnitSpinBox(what, "%", (low, 100.0), 100 * float(values_rel.get(name) or 0.0),
                                        decimals=2 if unset_text else 1, step=0.5, special=unset_text,
                                        tip=tip + unset_tip)
                      for name, (_row, what, tip) in _FIELDS.items()}

    def add_rows(self, form: QFormLayout) -> None:
        for name, spin in self.spins.items():
            form.addRow(_FIELDS[name][0], spin)

    def fractions(self) -> dict[str, float | None]:
        """Each option as the analysis takes it (a fraction; None: not stated)."""
        return {name: None if self.unset_text and spin.value() == 0 else round(spin.value() / 100, 6)
                for name, spin in self.spins.items()}
