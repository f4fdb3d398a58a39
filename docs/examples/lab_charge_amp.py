"""A lab's own amplifier driver: the complete example of docs/writing-a-driver.md.

The "ACME CA-2" is a charge amplifier on a serial line (9600 baud, 8N1). Each command is one
line ending in "\\n" and gets one line back:

    *IDN?            ->  ACME,CA-2,SN42,1.3
    GAIN?            ->  GAIN 100          output volts per input volt
    GAIN 100         ->  OK                (1, 10, 100 or 1000)
    FILTER?          ->  FILTER 30000      low-pass corner in Hz, 0 = off
    FILTER 30000     ->  OK
    OVL?             ->  OVL 0             1 = the output overloaded since the last RESET
    RESET            ->  OK                discharge the input (zero) and clear the overload
    anything wrong   ->  ERR <reason>

`ChargeAmplifier` plays the amplifier role (hopkinson.drivers.roles.AmplifierRole).
`FakeChargeAmp` is the same device in software, on a simulated serial line, for testing the
driver without the hardware.
"""

from __future__ import annotations

import os
import select
import threading

from hopkinson.drivers.base import TraceHook
from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.roles import AmplifierSettings
from hopkinson.drivers.serial_link import SerialLineDriver

GAINS = (1.0, 10.0, 100.0, 1000.0)


class ChargeAmplifier(SerialLineDriver):
    """The ACME CA-2 charge amplifier (module docstring)."""

    def __init__(self, port: str, *, baudrate: int = 9600, timeout_s: float = 1.0,
                 name: str = "", trace: TraceHook | None = None) -> None:
        super().__init__(port, baudrate=baudrate, timeout_s=timeout_s, name=name or f"ACME CA-2 {port}",
                         trace=trace)

    def query(self, command: str) -> str:
        """Send one line, return the reply line; an ERR reply is an InstrumentError."""
        reply = self.exchange(command.encode("ascii") + b"\n", command).decode("ascii", "replace").strip()
        if reply.startswith("ERR"):
            raise InstrumentError(self.name, command, "the amplifier refused", reply)
        return reply

    def _value(self, command: str) -> float:
        reply = self.query(command)
        head, _, value = reply.partition(" ")
        if head != command.rstrip("?"):
            raise InstrumentError(self.name, command, "reply is for another command", reply)
        try:
            return float(value)
        except ValueError:
            raise InstrumentError(self.name, command, "reply is not a number", reply) from None

    # -- the amplifier role ---------------------------------------------------------------------
    def identity(self) -> str:
        return self.query("*IDN?")

    def configure(self, *, gain: float, excitation_v: float, lowpass_hz: float) -> None:
        if excitation_v != 0:
            raise InstrumentError(self.name, "configure", f"a charge amplifier has no excitation "
                                  f"(asked {excitation_v:g} V): set amplifier.excitation_v = 0")
        if gain not in GAINS:
            raise InstrumentError(self.name, "configure", f"gain {gain:g} is not one of {GAINS}")
        for command in (f"GAIN {gain:g}", f"FILTER {lowpass_hz:g}"):
            if self.query(command) != "OK":
                raise InstrumentError(self.name, command, "expected OK")
        got = self.settings()
        if (got.gain, got.lowpass_hz) != (gain, lowpass_hz):
            raise InstrumentError(self.name, "configure", "settings did not stick",
                                  f"GAIN {got.gain:g}, FILTER {got.lowpass_hz:g}")

    def settings(self) -> AmplifierSettings:
        return AmplifierSettings(gain=self._value("GAIN?"), excitation_v=0.0, lowpass_hz=self._value("FILTER?"))

    def overloaded(self) -> bool:
        return self._value("OVL?") != 0

    def auto_zero(self) -> None:
        if self.query("RESET") != "OK":
            raise InstrumentError(self.name, "RESET", "expected OK")

    def set_shunt(self, on: bool) -> None:
        if on:
            raise InstrumentError(self.name, "shunt on", "the CA-2 has no shunt calibration")


class FakeChargeAmp:
    """The CA-2 in software, serving the device end of a simulated serial line:

        with PtyLine(byte_time_s(9600)) as line, FakeChargeAmp(line.device_fd):
            ChargeAmplifier(line.port)   # talks to it as to the real one
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.gain, self.filter_hz, self.overload = 1.0, 0.0, False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True, name="fake-ca2")

    def __enter__(self) -> FakeChargeAmp:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def _serve(self) -> None:
        buffer = b""
        while not self._stop.is_set():
            if not select.select([self.fd], [], [], 0.05)[0]:
                continue
            buffer += os.read(self.fd, 256)
            while b"\n" in buffer:
                line, buffer = buffer.split(b"\n", 1)
                os.write(self.fd, self.answer(line.decode("ascii", "replace").strip()).encode("ascii") + b"\n")

    def answer(self, command: str) -> str:
        try:
            return self._answer(command)
        except ValueError:  # a number that is not one
            return "ERR SYNTAX"

    def _answer(self, command: str) -> str:
        verb, _, arg = command.partition(" ")
        if verb == "*IDN?":
            return "ACME,CA-2,SN42,1.3"
        if verb in ("GAIN?", "FILTER?", "OVL?"):
            value = {"GAIN?": self.gain, "FILTER?": self.filter_hz, "OVL?": float(self.overload)}[verb]
            return f"{verb[:-1]} {value:g}"
        if verb == "GAIN" and arg and float(arg) in GAINS:
            self.gain = float(arg)
            return "OK"
        if verb == "FILTER" and arg:
            self.filter_hz = float(arg)
            return "OK"
        if verb == "RESET":
            self.overload = False
            return "OK"
        return "ERR SYNTAX"
