"""A signal conditioner set by hand (charge, IEPE or bridge amplifier without a computer link).

The technician sets gain, filter and sensitivity on the front panel and enters the same
values in rig.toml (`[amplifier] driver = "manual"`), the campaign plan or the panel. This
driver plays the amplifier role without any I/O: `settings()` returns what was entered
(source "entered"), so those values are recorded in the shot file like any instrument's
settings, and `configure()` refuses values that differ from what was entered (the software
cannot turn the knob: the technician must, and then enter the new values).

There is no overload signal: `overloaded()` is False and clipping is judged from the
digitizer's full-scale codes alone.
"""

from __future__ import annotations

import math

from hopkinson.drivers.base import InstrumentDriver, TraceHook
from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.roles import AmplifierSettings


class ManualConditioner(InstrumentDriver):
    """A conditioner whose settings are entered, not read (module docstring)."""

    def __init__(self, *, gain: float, excitation_v: float = 0.0, lowpass_hz: float = 0.0,
                 sensitivity_v_per_m_s2: float | None = None, identity: str = "",
                 name: str = "manual conditioner", trace: TraceHook | None = None) -> None:
        super().__init__(name, trace=trace)
        self._open_now = False
        self.enter(gain=gain, excitation_v=excitation_v, lowpass_hz=lowpass_hz,
                   sensitivity_v_per_m_s2=sensitivity_v_per_m_s2, identity=identity)

    def enter(self, *, gain: float, excitation_v: float = 0.0, lowpass_hz: float = 0.0,
              sensitivity_v_per_m_s2: float | None = None, identity: str = "") -> None:
        """The technician's values (from rig.toml, the plan or the panel); ValueError naming a
        value that cannot be a setting."""
        for key, value in (("gain", gain), ("excitation_v", excitation_v), ("lowpass_hz", lowpass_hz),
                           ("sensitivity_v_per_m_s2", sensitivity_v_per_m_s2 or 0.0)):
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{self.name}: {key} must be a finite number >= 0, got {value!r}")
        if gain <= 0:
            raise ValueError(f"{self.name}: gain must be > 0, got {gain!r}")
        self._settings = AmplifierSettings(gain=float(gain), excitation_v=float(excitation_v),
                                           lowpass_hz=float(lowpass_hz), source="entered",
                                           sensitivity_v_per_m_s2=sensitivity_v_per_m_s2 or None,
                                           identity=identity)

    def _open(self) -> None:
        self._open_now = True

    def _close_link(self) -> None:
        self._open_now = False

    def _link_open(self) -> bool:
        return self._open_now

    def identity(self) -> str:
        """What the technician entered (make, model, serial), or a note that it is manual."""
        return self._settings.identity or "manual conditioner (settings entered by hand)"

    def settings(self) -> AmplifierSettings:
        return self._settings

    def gain(self) -> float:
        return self._settings.gain

    def configure(self, *, gain: float, excitation_v: float, lowpass_hz: float) -> None:
        """Check that the asked-for settings are the entered ones (nothing can be set)."""
        asked = AmplifierSettings(gain=gain, excitation_v=excitation_v, lowpass_hz=lowpass_hz)
        differences = self._settings.differences(asked)
        if differences:
            raise InstrumentError(self.name, "configure", "set by hand: the asked-for settings differ from the "
                                  f"entered ones ({'; '.join(differences)}); set the conditioner and enter its values")

    def overloaded(self) -> bool:
        """No overload output: always False (the digitizer's full scale judges clipping)."""
        return False

    def auto_zero(self) -> None:
        """Nothing to do (zeroed by hand)."""

    def set_shunt(self, on: bool) -> None:
        """Shunt calibration is a front-panel switch: only `off` is accepted."""
        if on:
            raise InstrumentError(self.name, "shunt on", "set by hand: switch the shunt on at the conditioner")
