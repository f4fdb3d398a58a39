"""Rig status at a glance: each instrument's connection (its identity in the lamp's tooltip, what
is wrong under it when it is not connected), the reservoir pressure and fixture vacuum (live),
and the interlocks as lamps.

Lamp colours: green = holds; red = does not hold where it must (door open, e-stop tripped,
overpressure, amplifier overloaded, or vacuum/digitizer lost while armed); amber = not reached
yet but the sequence gets there itself (the fixture vacuum before EVACUATE, the digitizer before
ARM); grey = not read in this state. The tooltip says what the rig reported.
"""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFrame, QGridLayout, QLabel, QVBoxLayout, QWidget

from hopkinson.rig.config import LimitsConfig
from hopkinson.rig.events import Reading
from hopkinson.rig.interlocks import INTERLOCKS
from hopkinson.ui.widgets import LampLabel, section_title
from hopkinson.ui.worker import INSTRUMENT_KEYS, INSTRUMENT_LABELS, InstrumentLink

INTERLOCK_CAPTIONS = {
    "door": "Door / guard closed",
    "clamp": "Fixture clamped",
    "estop": "E-stop healthy",
    "vacuum": "Fixture vacuum",
    "pressure": "Reservoir pressure",
    "digitizer": "Digitizer armed",
    "amplifier": "Amplifier not overloaded",
}
# Interlocks the sequence itself brings about, and the states from which they must hold.
_REACHED_BY_SEQUENCE = {"vacuum": ("CHARGE", "ARM", "FIRE"), "digitizer": ("ARM", "FIRE")}
_NOT_CHECKED = {"vacuum": "reached in EVACUATE", "digitizer": "checked once armed",
                "pressure": "checked while charging and armed", "amplifier": "amplifier not read"}


def interlock_level(name: str, ok: bool | None, state: str) -> str:
    """The lamp level of one interlock in a sequencer state (module docstring)."""
    if ok is None:
        return "unknown"
    if ok:
        return "ok"
    if name in _REACHED_BY_SEQUENCE and state not in _REACHED_BY_SEQUENCE[name]:
        return "warn"
    return "fault"


class StatusPanel(QWidget):
    """Instruments, gauges and interlocks; fed by `set_links` and `show_reading`."""

    def __init__(self, limits: LimitsConfig, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.limits = limits
        self.instrument_lamps: dict[str, LampLabel] = {}
        self.instrument_details: dict[str, QLabel] = {}
        self.interlock_lamps: dict[str, LampLabel] = {}
        self.interlocks: dict[str, bool] = {}
        self.reservoir_pressure_bar: float | None = None
        self.fixture_vacuum_mbar: float | None = None

        layout = QVBoxLayout(self)
        layout.setContentsMargins(8, 8, 8, 8)
        layout.setSpacing(4)

        layout.addWidget(section_title("Instruments"))
        for key in INSTRUMENT_KEYS:
            lamp = LampLabel(INSTRUMENT_LABELS[key])
            lamp.caption.setStyleSheet("font-weight: 600;")
            detail = QLabel("connecting…")
            detail.setStyleSheet("color: #5f6368; font-size: 9pt; margin-left: 22px;")
            detail.setWordWrap(True)
            detail.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            self.instrument_lamps[key] = lamp
            self.instrument_details[key] = detail
            layout.addWidget(lamp)
            layout.addWidget(detail)

        layout.addSpacing(6)
        layout.addWidget(_rule())
        layout.addWidget(section_title("Gauges"))
        gauges = QGridLayout()
        gauges.setHorizontalSpacing(12)
        gauges.setVerticalSpacing(0)
        self.pressure_value = _big_value()
        self.vacuum_value = _big_value()
        self.pressure_note = _small_note(f"gauge; limit {limits.max_pressure_bar:g} bar")
        self.vacuum_note = _small_note(f"absolute; fire below {limits.fixture_vacuum_max_mbar:g} mbar")
        gauges.addWidget(QLabel("Reservoir"), 0, 0)
        gauges.addWidget(QLabel("Fixture vacuum"), 0, 1)
        gauges.addWidget(self.pressure_value, 1, 0)
        gauges.addWidget(self.vacuum_value, 1, 1)
        gauges.addWidget(self.pressure_note, 2, 0)
        gauges.addWidget(self.vacuum_note, 2, 1)
        layout.addLayout(gauges)

        layout.addSpacing(6)
        layout.addWidget(_rule())
        layout.addWidget(section_title("Interlocks"))
        grid = QGridLayout()
        grid.setHorizontalSpacing(10)
        grid.setVerticalSpacing(3)
        for i, name in enumerate(INTERLOCKS):
            lamp = LampLabel(INTERLOCK_CAPTIONS[name])
            lamp.set_state("unknown", "not read yet")
            self.interlock_lamps[name] = lamp
            grid.addWidget(lamp, i // 2, i % 2)
        layout.addLayout(grid)
        self._show_gauges()

    # -- updates ----------------------------------------------------------------------------
    def set_links(self, links: dict[str, InstrumentLink]) -> None:
        """Show each instrument's connection (lamp) and identity or problem (text)."""
        levels = {"connected": "ok", "error": "warn", "disconnected": "fault", "unknown": "unknown"}
        for key, link in links.items():
            lamp, detail = self.instrument_lamps[key], self.instrument_details[key]
            if link.status == "connected":
                text = link.identity or "connected"
            elif link.status == "error":
                text = f"answering, but: {link.problem}"
            elif link.status == "disconnected":
                text = f"DISCONNECTED — {link.problem}. Check the cable/power; retrying."
            else:
                text = "connecting…"
            detail.setText(text)
            detail.setToolTip(link.address)
            detail.setVisible(link.status != "connected")  # connected: its identity is in the lamp's tooltip
            lamp.set_state(levels[link.status], f"{link.label}: {link.status}\n{link.identity or link.address}"
                                                f"\n{link.problem}".rstrip())

    def show_reading(self, event: Reading) -> None:
        """Update the gauges and lamps from a Reading event."""
        self.reservoir_pressure_bar = event.reservoir_pressure_bar
        self.fixture_vacuum_mbar = event.fixture_vacuum_mbar
        interlocks: dict[str, bool] = dict(event.interlocks)
        self.interlocks = interlocks
        for name, lamp in self.interlock_lamps.items():
            ok = interlocks.get(name)
            text = ("holds" if ok else event.details.get(name, "does not hold")) if ok is not None \
                else _NOT_CHECKED.get(name, "not read in this state")
            lamp.set_state(interlock_level(name, ok, event.state), f"{INTERLOCK_CAPTIONS[name]}: {text}")
        self._show_gauges()

    def show_disconnected(self) -> None:
        """The controller is not answering: gauges and lamps unknown."""
        self.reservoir_pressure_bar = self.fixture_vacuum_mbar = None
        self.interlocks = {}
        for lamp in self.interlock_lamps.values():
            lamp.set_state("unknown", "the valve/vacuum controller is not answering")
        self._show_gauges()

    def _show_gauges(self) -> None:
        p, v = self.reservoir_pressure_bar, self.fixture_vacuum_mbar
        self.pressure_value.setText("— bar" if p is None else f"{p:.3f} bar")
        self.vacuum_value.setText("— mbar" if v is None else f"{v:.1f} mbar")
        over = p is not None and p > self.limits.max_pressure_bar
        self.pressure_value.setStyleSheet(_BIG + ("color: #d0312d;" if over else ""))
        good = v is not None and v <= self.limits.fixture_vacuum_max_mbar
        self.vacuum_value.setStyleSheet(_BIG + ("color: #2e9d43;" if good else ""))


_BIG = "font-size: 15pt; font-weight: 600; font-family: 'DejaVu Sans Mono', monospace;"


def _big_value() -> QLabel:
    label = QLabel("—")
    label.setStyleSheet(_BIG)
    return label


def _small_note(text: str) -> QLabel:
    label = QLabel(text)
    label.setStyleSheet("color: #5f6368; font-size: 8pt;")
    return label


def _rule() -> QFrame:
    line = QFrame()
    line.setFrameShape(QFrame.Shape.HLine)
    line.setStyleSheet("color: #dadce0;")
    return line
