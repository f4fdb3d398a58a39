"""Instrument errors: every one names the instrument, the command and what came back."""

from __future__ import annotations


class InstrumentError(RuntimeError):
    """An instrument did not do what was asked: connection lost, bad reply, timeout, refusal.

    instrument: the instrument's name as configured (e.g. "valve controller 127.0.0.1:5020").
    command: what was sent (SCPI text, Modbus function and address, serial line).
    reply: what came back (truncated for display), or "" for none.
    """

    def __init__(self, instrument: str, command: str, problem: str, reply: str | bytes = "") -> None:
        self.instrument = instrument
        self.command = command
        self.problem = problem
        if isinstance(reply, bytes):
            reply = reply[:80].decode("ascii", "backslashreplace")
        self.reply = reply[:200]
        text = f"{instrument}: {command!r}: {problem}"
        if self.reply:
            text += f" (reply: {self.reply!r})"
        super().__init__(text)


class InstrumentTimeout(InstrumentError):
    """No reply within the configured timeout."""


class InstrumentConnectionError(InstrumentError):
    """Could not connect, or the connection dropped."""
