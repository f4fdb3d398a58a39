"""Declared instrument settings: one declaration per setting, read by the driver and the config.

Like PyMeasure's ``Instrument.control(get_command, set_command, docs, validator=, values=)``, a
`Control` states once how a setting is read and written on the wire and which values it may
take. The driver sends and parses with it (drivers/amplifier.py); the configuration checks a
file's value against the same declaration before any instrument is opened (rig/config.py), so
the two can never disagree.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Control:
    """One setting: its commands, its allowed values (a set or an inclusive range) and its unit.

    name: the keyword and config key (e.g. "gain"); label: how messages call it; get_command:
    the query ("GAIN?"); set_command: the command with ``{}`` for the value's text
    ("GAIN {}"); values: the allowed values, or limits: the inclusive (low, high) range; words:
    values sent and read as words ({0.0: "OFF"}); text: how a number is written ("{:g}").
    """

    name: str
    label: str
    get_command: str
    set_command: str
    values: tuple[float, ...] = ()
    limits: tuple[float, float] | None = None
    unit: str = ""
    words: dict[float, str] = field(default_factory=dict)
    text: str = "{:g}"

    def allows(self, value: float) -> bool:
        """True when `value` is one of the values, or within the limits."""
        if self.limits is not None:
            return self.limits[0] <= value <= self.limits[1]
        return value in self.values

    def allowed_text(self) -> str:
        """The allowed values as messages show them: "1, 2, 5" or "0.5 .. 10 V"."""
        unit = f" {self.unit}" if self.unit else ""
        if self.limits is not None:
            return f"{self.limits[0]:g} .. {self.limits[1]:g}{unit}"
        return ", ".join(f"{v:g}" for v in self.values) + unit

    def check(self, value: float) -> None:
        """ValueError naming the setting, the value and what it may be."""
        if not self.allows(value):
            unit = f" {self.unit}" if self.unit else ""
            how = "outside" if self.limits is not None else "not one of"
            raise ValueError(f"{self.label} {value:g}{unit} {how} {self.allowed_text()}")

    def command(self, value: float) -> str:
        """The set command for `value` (checked first)."""
        self.check(value)
        return self.set_command.format(self.words.get(value, self.text.format(value)))

    def parse(self, reply: str) -> float:
        """The value of a query's reply; ValueError when it is neither a number nor a word."""
        for value, word in self.words.items():
            if reply == word:
                return value
        return float(reply)
