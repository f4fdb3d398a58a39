"""Input fields that behave as a technician expects at a rig.

- The mouse wheel changes a spin box or a drop-down only when it has the keyboard focus
  (clicked or tabbed into): scrolling a form over its fields scrolls the form and changes
  nothing.
- `UnitSpinBox` states its unit in the field (its suffix) and takes any number typed, then
  refuses one outside its plausible range: the field keeps its last good value and `refused`
  carries one line naming the field, the value, the range and the unit ("Sensor f_n: 27000 kHz
  is outside 1 … 300 kHz; kept 27 kHz"), never a keystroke silently dropped. Code that uses the
  value listens to `value_accepted`, which only ever carries plausible values.
"""

from __future__ import annotations

import math

from PySide6.QtCore import QSize, Qt, Signal
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import QComboBox, QDoubleSpinBox, QSpinBox, QWidget

TYPED_LIMIT = 1e12  # what may be typed at all: the plausible range is checked after typing


class FocusWheel:
    """Mixed into a field before its Qt class: the wheel changes it only while it has the focus;
    without, the event goes on to the form around it, which scrolls."""

    def wheelEvent(self, event: QWheelEvent) -> None:  # noqa: N802 (Qt's name)
        if self.hasFocus():  # type: ignore[attr-defined]
            super().wheelEvent(event)  # type: ignore[misc]
        else:
            event.ignore()


class UnitSpinBox(FocusWheel, QDoubleSpinBox):
    """A number with its unit and plausible range (module docstring).

    what: the field's name in messages; unit: shown after the number ("" for none);
    plausible: (low, high) in that unit; special: the text of a "no value" choice (0 shows it;
    always accepted), "" for none.
    """

    refused = Signal(str)  # one line: what was refused and why
    value_accepted = Signal(float)  # a new plausible value (typed, set, or the special one)

    def __init__(self, what: str, unit: str, plausible: tuple[float, float], value: float, *, decimals: int = 2,
                 step: float = 1.0, special: str = "", tip: str = "", parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.what, self.unit, self.special = what, unit, special
        self.plausible = plausible
        self.setDecimals(decimals)
        self.setRange(0.0 if special or plausible[0] >= 0 else -TYPED_LIMIT, TYPED_LIMIT)
        self.setSingleStep(step)
        if unit:
            self.setSuffix(f" {unit}")
        if special:
            self.setSpecialValueText(special)
        self.setKeyboardTracking(False)  # a typed number counts once typed (Enter, Tab, focus out)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.setToolTip(self._tip(tip))
        self._good = value if self.is_plausible(value) else plausible[0]
        super().setValue(self._good)
        self.valueChanged.connect(self._check)

    def _tip(self, tip: str) -> str:
        low, high = self.plausible
        span = f"{_number(low)} … {_number(high)} {self.unit}".rstrip()
        return (tip + "\n" if tip else "") + f"plausible: {span}" + (f"; 0 = {self.special}" if self.special else "")

    def set_plausible(self, low: float, high: float) -> None:
        """A new plausible range (e.g. the rig's pressure limits); the value is kept when inside."""
        self.plausible = (low, high)
        self.setToolTip(self._tip(""))
        if not self.is_plausible(self.value()):
            self._check(self.value())

    def is_plausible(self, value: float) -> bool:
        if self.special and value == 0.0:
            return True
        low, high = self.plausible
        return math.isfinite(value) and low <= value <= high

    def _check(self, value: float) -> None:
        if self.is_plausible(value):
            self._good = value
            self.value_accepted.emit(value)
            return
        kept = self._good
        self.blockSignals(True)
        try:
            super().setValue(kept)
        finally:
            self.blockSignals(False)
        low, high = self.plausible
        unit = f" {self.unit}" if self.unit else ""
        kept_text = self.special if self.special and kept == 0.0 else f"{_number(kept)}{unit}"
        self.refused.emit(f"{self.what}: {_number(value)}{unit} is outside {_number(low)} … {_number(high)}{unit}; "
                          f"kept {kept_text}")

    def sizeHint(self) -> QSize:  # noqa: N802 (Qt's name)
        return self._fit(super().sizeHint())

    def minimumSizeHint(self) -> QSize:  # noqa: N802 (Qt's name)
        return self._fit(super().minimumSizeHint())

    def _fit(self, hint: QSize) -> QSize:
        """As wide as its plausible values need (Qt sizes it for TYPED_LIMIT, which nobody types)."""
        texts = [self.textFromValue(v) + self.suffix() for v in self.plausible] + [self.special]
        need = max(self.fontMetrics().horizontalAdvance(t) for t in texts) + 44  # arrows and frame
        return QSize(min(hint.width(), need), hint.height())


class IntSpinBox(FocusWheel, QSpinBox):
    """A whole number whose wheel works only with the focus (module docstring)."""

    def __init__(self, low: int, high: int, value: int, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setRange(low, high)
        self.setValue(value)
        self.setKeyboardTracking(False)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)


class ComboBox(FocusWheel, QComboBox):
    """A drop-down whose wheel works only with the focus (module docstring)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)


def _number(value: float) -> str:
    """A number as a technician writes it: 27000, 2.5, 0.0001, 1e+12."""
    return f"{value:.6g}"
