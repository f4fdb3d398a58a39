"""Bridge amplifier of the accelerometer, over a serial line (pyserial).

Protocol (line-based ASCII, designed for this rig; the simulated amplifier speaks it too)
------------------------------------------------------------------------------------------
Every line, both ways, is ``<payload>*<XX>\\n``: XX is the NMEA-0183 style checksum, two
upper-case hex digits of the XOR of all payload bytes. ``\\r\\n`` is accepted as the end
of a line. The checksum is optional from host to amplifier (so a person can type into a
terminal); the driver always sends it, and the amplifier answers a wrong one with
``<VERB> ERR CHECKSUM``. Replies always carry the checksum and begin with the verb of the
command they answer (an echo check: a stale or foreign reply is never taken for the answer).

====================  ======================  ==========================================
command               reply                   meaning
====================  ======================  ==========================================
``*IDN?``             ``*IDN v,model,sn,fw``  identity
``EXC <volts>``       ``EXC OK``              bridge excitation, 0.5 … 10 V (EXCITATION)
``EXC?``              ``EXC 5.000``
``GAIN <g>``          ``GAIN OK``             gain, one of GAIN.values
``GAIN?``             ``GAIN 10``
``LP <hz>|OFF``       ``LP OK``               low-pass filter corner, one of LOWPASS.values
``LP?``               ``LP 200000`` / ``LP OFF``
``AZ``                ``AZ OK``               auto-zero (bridge balance); clears overload
``SHUNT ON|OFF``      ``SHUNT OK``            shunt calibration resistor in/out
``SHUNT?``            ``SHUNT ON|OFF``
``OVL?``              ``OVL 0|1``             output overload (latched)
``OVL CLR``           ``OVL OK``              clear the overload latch
``OUT?``              ``OUT 0.0123``          DC output monitor, volts
====================  ======================  ==========================================

An error is ``<VERB> ERR <REASON>`` (UNKNOWN, RANGE, SYNTAX, CHECKSUM).

The three settings are declared once (`SETTINGS`, drivers/controls.py: their commands and
allowed values); rig/config.py checks a rig file's [amplifier] against the same declarations.

Example bytes: the driver sends ``b"GAIN 20*23\\n"``; the amplifier answers ``b"GAIN OK*25\\n"``.

The driver retries a command `retries` times after a timeout, a bad checksum or an overlong
line (every command here is idempotent), flushing the input first; then it raises an
InstrumentError that names the amplifier, the command and the reply. The port is opened
exclusively and every read is bounded (drivers/serial_link.py).
"""

from __future__ import annotations

from dataclasses import dataclass

from hopkinson.drivers.base import TraceHook
from hopkinson.drivers.controls import Control
from hopkinson.drivers.errors import InstrumentError, InstrumentTimeout
from hopkinson.drivers.roles import AmplifierSettings
from hopkinson.drivers.serial_link import SerialLineDriver

EXCITATION = Control("excitation_v", "excitation", "EXC?", "EXC {}", limits=(0.5, 10.0), unit="V", text="{:.3f}")
GAIN = Control("gain", "gain", "GAIN?", "GAIN {}", values=(1, 2, 5, 10, 20, 50, 100, 200, 500, 1000))
LOWPASS = Control("lowpass_hz", "low-pass", "LP?", "LP {}", unit="Hz", words={0.0: "OFF"},
                  values=(0.0, 1e3, 2e3, 5e3, 10e3, 20e3, 50e3, 100e3, 200e3))  # 0 = filter off
SETTINGS = (EXCITATION, GAIN, LOWPASS)  # in the order `configure` sets them
MAX_LINE_BYTES = 256


class FramingError(ValueError):
    """A line that is not ``<payload>*<XX>`` with the right checksum."""


def checksum(payload: str | bytes) -> str:
    """NMEA-style checksum: XOR of every byte of the payload, as two upper-case hex digits."""
    data = payload.encode("ascii") if isinstance(payload, str) else payload
    value = 0
    for byte in data:
        value ^= byte
    return f"{value:02X}"


def frame(payload: str) -> bytes:
    """One line on the wire: ``<payload>*<XX>\\n``."""
    if "\n" in payload or "\r" in payload:
        raise ValueError("payload must be one line")
    return f"{payload}*{checksum(payload)}\n".encode("ascii")


def parse_line(line: bytes, require_checksum: bool = True) -> str:
    """The payload of one received line; FramingError for a missing or wrong checksum."""
    if not line.endswith(b"\n"):
        raise FramingError("line not terminated by \\n")
    body = line.rstrip(b"\r\n")
    try:
        text = body.decode("ascii")
    except UnicodeDecodeError as exc:
        raise FramingError("non-ASCII bytes in line") from exc
    payload, star, digits = text.rpartition("*")
    if not star or len(digits) != 2 or not all(c in "0123456789ABCDEFabcdef" for c in digits):
        if require_checksum:
            raise FramingError("no *XX checksum at the end of the line")
        return text
    if digits.upper() != checksum(payload):
        raise FramingError(f"checksum mismatch: line says {digits.upper()}, payload gives {checksum(payload)}")
    return payload


@dataclass(frozen=True)
class AmplifierStatus:
    """Settings and state of the bridge amplifier."""

    identity: str
    excitation_v: float
    gain: float
    lowpass_hz: float  # 0 = filter off
    shunt_on: bool
    overloaded: bool
    output_v: float


class BridgeAmplifier(SerialLineDriver):
    """Driver of the accelerometer bridge amplifier (serial, protocol in the module docstring)."""

    max_line_bytes = MAX_LINE_BYTES

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 115200,
        timeout_s: float = 1.0,
        retries: int = 1,
        name: str | None = None,
        trace: TraceHook | None = None,
    ) -> None:
        super().__init__(port, baudrate=baudrate, timeout_s=timeout_s, name=name or f"bridge amplifier {port}",
                         trace=trace)
        if not 0 <= retries <= 10:
            raise ValueError(f"{self.name}: retries must be 0..10, got {retries}")
        self.retries = retries

    # -- operations -----------------------------------------------------------------------
    def identity(self) -> str:
        """Vendor, model, serial number and firmware."""
        return self.query("*IDN?")

    def set_excitation_v(self, excitation_v: float) -> None:
        """Bridge excitation voltage, within EXCITATION.limits."""
        self._set(EXCITATION, excitation_v)

    def excitation_v(self) -> float:
        return self._get(EXCITATION)

    def set_gain(self, gain: float) -> None:
        """Amplifier gain, one of GAIN.values."""
        self._set(GAIN, gain)

    def gain(self) -> float:
        return self._get(GAIN)

    def set_lowpass_hz(self, lowpass_hz: float) -> None:
        """Low-pass corner, one of LOWPASS.values (0 switches the filter off)."""
        self._set(LOWPASS, lowpass_hz)

    def lowpass_hz(self) -> float:
        """The low-pass corner in Hz; 0 when the filter is off."""
        return self._get(LOWPASS)

    def auto_zero(self) -> None:
        """Balance the bridge (zero the output); also clears the overload latch."""
        self._expect_ok("AZ")

    def set_shunt(self, on: bool) -> None:
        """Switch the shunt-calibration resistor in (True) or out."""
        self._expect_ok(f"SHUNT {'ON' if on else 'OFF'}")

    def shunt(self) -> bool:
        return self._choice("SHUNT?", {"ON": True, "OFF": False})

    def overloaded(self) -> bool:
        """True when the output has overloaded since the last clear (latched)."""
        return self._choice("OVL?", {"1": True, "0": False})

    def clear_overload(self) -> None:
        self._expect_ok("OVL CLR")

    def output_v(self) -> float:
        """DC output monitor in volts."""
        return self._number("OUT?")

    def configure(self, *, gain: float, excitation_v: float, lowpass_hz: float) -> None:
        """Set excitation, gain and low-pass (`SETTINGS`), then read them back to check."""
        wanted = {"excitation_v": excitation_v, "gain": gain, "lowpass_hz": lowpass_hz}
        for control in SETTINGS:
            self._set(control, wanted[control.name])
        got = tuple(self._get(control) for control in SETTINGS)
        if abs(got[0] - excitation_v) > 1e-3 or got[1] != gain or got[2] != lowpass_hz:
            raise InstrumentError(self.name, "configure", "settings did not stick",
                                  f"EXC {got[0]}, GAIN {got[1]:g}, LP {got[2]:g}")

    def settings(self) -> AmplifierSettings:
        """Gain, excitation and low-pass as the amplifier reports them."""
        return AmplifierSettings(gain=self.gain(), excitation_v=self.excitation_v(), lowpass_hz=self.lowpass_hz())

    def status(self) -> AmplifierStatus:
        """Everything the amplifier reports."""
        return AmplifierStatus(
            identity=self.identity(), excitation_v=self.excitation_v(), gain=self.gain(),
            lowpass_hz=self.lowpass_hz(), shunt_on=self.shunt(), overloaded=self.overloaded(),
            output_v=self.output_v(),
        )

    # -- protocol -----------------------------------------------------------------------
    def query(self, command: str) -> str:
        """Send one command; return the reply's value (the text after the echoed verb).

        Raises InstrumentTimeout (no complete line in time), InstrumentError for a bad
        checksum, a reply to another command, or an ``ERR`` reply.
        """
        verb = command.split(" ", 1)[0].rstrip("?")
        last: InstrumentError | None = None
        for _attempt in range(self.retries + 1):
            try:
                payload = self._exchange(command)
            except (InstrumentTimeout, _GarbledReply) as exc:
                last = exc if isinstance(exc, InstrumentError) else InstrumentError(
                    self.name, command, str(exc), exc.line)
                continue
            head, _, value = payload.partition(" ")
            if head != verb:
                last = InstrumentError(self.name, command, f"reply is not for {verb!r}", payload)
                continue
            if value.startswith("ERR"):
                raise InstrumentError(self.name, command, f"amplifier refused: {value[3:].strip() or 'error'}",
                                      payload)
            return value
        assert last is not None
        raise last

    def _exchange(self, command: str) -> str:
        try:
            line = self.exchange(frame(command), command)
        except InstrumentTimeout:
            raise
        except InstrumentError as exc:
            if exc.problem.startswith("reply longer"):  # line noise ate the end of line
                raise _GarbledReply(exc.problem, exc.reply.encode("ascii", "replace")) from exc
            raise
        try:
            return parse_line(line)
        except FramingError as exc:
            raise _GarbledReply(str(exc), line) from exc

    def _set(self, control: Control, value: float) -> None:
        try:
            command = control.command(value)
        except ValueError as exc:
            raise ValueError(f"{self.name}: {exc}") from None
        self._expect_ok(command)

    def _get(self, control: Control) -> float:
        value = self.query(control.get_command)
        try:
            return control.parse(value)
        except ValueError:
            raise InstrumentError(self.name, control.get_command, "reply is not a number", value) from None

    def _expect_ok(self, command: str) -> None:
        value = self.query(command)
        if value != "OK":
            raise InstrumentError(self.name, command, "expected OK", value)

    def _number(self, command: str) -> float:
        return self._to_float(command, self.query(command))

    def _to_float(self, command: str, value: str) -> float:
        try:
            return float(value)
        except ValueError:
            raise InstrumentError(self.name, command, "reply is not a number", value) from None

    def _choice(self, command: str, choices: dict[str, bool]) -> bool:
        value = self.query(command)
        if value not in choices:
            raise InstrumentError(self.name, command, f"reply is not one of {', '.join(choices)}", value)
        return choices[value]


class _GarbledReply(Exception):
    def __init__(self, problem: str, line: bytes) -> None:
        super().__init__(problem)
        self.line = line
